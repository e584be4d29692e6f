"""004's H-infinity gain (host/filters/hinf.py): the LMI (2.15) as 004 writes it, the gain's
stability, its gamma confirmed on the unit circle and by Monte Carlo, gamma minimal, and 004's
eq. 5.1 against ours. The tests that solve need cvxpy and Clarabel (the `lmi` extra, which
scripts/test installs, so CI runs them)."""
from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from navtwin.cli.main import missing_extra
from navtwin.common.extras import MissingExtra
from navtwin.host.filters import hinf
from navtwin.host.filters.hinf import ErrorSystem, HinfFilter, feasible, lmi, solve_gain

needs_cvxpy = pytest.mark.skipif(
    importlib.util.find_spec("cvxpy") is None or importlib.util.find_spec("clarabel") is None,
    reason="cvxpy/Clarabel not installed: pip install 'navtwin[lmi]' (scripts/test installs it)")

#: 004's first training area: B = D = I, T = 1 s, E's entry 1.2 ms (eq. 5.1).
PAPER = dict(T=1.0, dt=0.0012, process=1.0, measurement=1.0)
#: Weighted, with a sampling-time error large enough for E beta to matter (0.1 s of 1 s).
WEIGHTED = dict(T=1.0, dt=0.1, process=[0.5, 0.5, 0.2, 0.2], measurement=[0.2, 0.2, 0.1, 0.1])


@pytest.fixture(scope="module", params=[PAPER, WEIGHTED], ids=["paper", "weighted"])
def gain(request):
    return solve_gain(**request.param)


def rho(M: np.ndarray) -> float:
    return float(np.abs(np.linalg.eigvals(M)).max())


def error_system(gain):
    """A~ = A - Bf C, B~ = B1 - Bf D1 (2.11)."""
    s = gain.system
    return s.A - gain.Bf @ s.C, s.B1 - gain.Bf @ s.D1


def peak(At, Bt, L, n=4001):
    """The H-infinity norm of L (zI - A~)^-1 B~: the largest singular value over z = e^jw,
    a grid on [0, pi] refined by golden-section around its best point; (norm, w, input)."""
    def sv(w):
        G = L @ np.linalg.solve(np.exp(1j * w) * np.eye(len(At)) - At, Bt)
        _, s, Vh = np.linalg.svd(G)
        return s[0], Vh[0].conj()

    ws = np.linspace(0.0, np.pi, n)
    i = int(np.argmax([sv(w)[0] for w in ws]))
    lo, hi = ws[max(i - 1, 0)], ws[min(i + 1, n - 1)]
    r = (np.sqrt(5) - 1) / 2
    for _ in range(60):
        a, b = hi - r * (hi - lo), lo + r * (hi - lo)
        lo, hi = (lo, b) if sv(a)[0] >= sv(b)[0] else (a, hi)
    w = (lo + hi) / 2
    s, v = sv(w)
    return s, w, v


def test_lmi_is_2_15_and_its_schur_complement_counts_A_twice():
    """np.block(lmi(...)) is (2.15) block by block; its Schur complement on the last four
    block rows is (2.16)'s left side with A~'P A~ twice: 004's slip at (2.19)."""
    rng = np.random.default_rng(1)
    es = ErrorSystem.build(1.0, 0.05, [1, 2, 3, 4], [0.5, 0.6, 0.7, 0.8])
    X = rng.normal(size=(4, 4))
    P, Q, g = X @ X.T + 4 * np.eye(4), rng.normal(size=(4, 4)), 7.0
    M = np.block(lmi(es, P, Q, g))
    assert M.shape == (28, 28) and np.array_equal(M, M.T)
    At = es.A - np.linalg.solve(P, Q) @ es.C
    Bt = es.B1 - np.linalg.solve(P, Q) @ es.D1
    np.testing.assert_allclose(M[:4, 12:16], At.T @ P, atol=1e-12)  # A'P - C'Q' = A~'P
    np.testing.assert_allclose(M[4:12, 12:16], Bt.T @ P, atol=1e-12)  # B1'P - D1'Q' = B~'P
    np.testing.assert_allclose(M[24:28, :4], P @ es.E, atol=0)
    # Schur complement: the first two block rows against diag(-P, -P, -I, -P)
    K, R = M[:12, 12:], M[12:, 12:]
    S = M[:12, :12] - K @ np.linalg.solve(R, K.T)
    L, E = es.L, es.E
    top = -P + 2 * At.T @ P @ At + L.T @ L + E.T @ P @ E
    expected = np.block([[top, At.T @ P @ Bt], [Bt.T @ P @ At, -g * np.eye(8) + Bt.T @ P @ Bt]])
    np.testing.assert_allclose(S, expected, rtol=1e-10, atol=1e-9)


@needs_cvxpy
def test_the_solution_satisfies_2_15(gain):
    s = gain.system
    g = (gain.gamma / s.weight) ** 2
    M = np.block(lmi(s.scaled(s.weight), gain.P, gain.Q, g))
    assert np.linalg.eigvalsh((M + M.T) / 2).max() < 0
    assert np.linalg.eigvalsh(gain.P).min() > 0
    np.testing.assert_allclose(gain.P @ gain.Bf, gain.Q, atol=1e-9)  # Q = P Bf (2.24)
    np.testing.assert_allclose(gain.Af, s.A - gain.Bf, atol=0)       # (2.25), C = I


@needs_cvxpy
def test_error_system_is_stable_and_mean_square_stable(gain):
    """(a): A~ stable, also at beta = +-3 (three sigma of the sampling-time error), and (2.11)
    mean-square stable: E[e e'] evolves by A~ (x) A~ + E (x) E (beta zero-mean, unit variance)."""
    At, _ = error_system(gain)
    E = gain.system.E
    assert rho(At) < 1
    assert rho(At + 3 * E) < 1 and rho(At - 3 * E) < 1
    assert rho(np.kron(At, At) + np.kron(E, E)) < 1


@needs_cvxpy
def test_gamma_bounds_the_worst_case_gain(gain):
    """(b): the deterministic part's H-infinity norm (a sweep of the unit circle) is at most
    gamma, and so is the stochastic system's energy gain for the worst-case input (the peak's
    singular vector as a sinusoid), mean over Monte Carlo runs of beta."""
    At, Bt = error_system(gain)
    L, E = gain.system.L, gain.system.E
    norm, w, v = peak(At, Bt, L)
    assert norm <= gain.gamma * (1 + 1e-9)
    assert norm >= 0.9 * gain.gamma  # (2.15)'s bound is not loose: the ratio below can fail
    v = v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))]))  # real at w = 0
    rng = np.random.default_rng(21)
    runs, steps = 200, 600
    k = np.arange(steps)
    s = np.real(v[None, :] * np.exp(1j * w * k)[:, None])  # steps x 8
    beta = rng.standard_normal((runs, steps))
    e = np.zeros((runs, 4))
    z2 = np.zeros(runs)
    for i in range(steps):
        z2 += np.sum((e @ L.T) ** 2, axis=1)
        e = e @ At.T + beta[:, i, None] * (e @ E.T) + s[i] @ Bt.T
    ratio = z2.mean() / np.sum(s ** 2)
    assert ratio <= gain.gamma ** 2
    assert ratio >= 0.8 * norm ** 2  # the input is the worst case: near the peak gain


@needs_cvxpy
def test_gamma_is_minimal(gain):
    """(c): with gamma^2 fixed 1 % below the optimum (2.15) has no solution; 1 % above it has."""
    assert not feasible(gain.system, gain.gamma * np.sqrt(0.99))
    assert feasible(gain.system, gain.gamma * np.sqrt(1.01))


@needs_cvxpy
def test_2_15_is_conservative():
    """The exact bounded-real inequality of (2.11), (2.15) without its fourth block row and
    column (A~'P A~ once, as in 2.16), reaches a lower gamma than (2.15): 1.8459 against 1.8496."""
    import cvxpy as cp

    gain = solve_gain(**PAPER)
    es = gain.system
    P, Q, g = cp.Variable((4, 4), symmetric=True), cp.Variable((4, 4)), cp.Variable()
    keep = [0, 1, 2, 4, 5]
    M = cp.bmat([[row[j] for j in keep] for i, row in enumerate(lmi(es, P, Q, g)) if i in keep])
    eps = hinf.EPS * np.eye(M.shape[0])
    cp.Problem(cp.Minimize(g), [(M + M.T) / 2 << -eps, P >> hinf.EPS * np.eye(4)]).solve(solver=cp.CLARABEL)
    exact = float(np.sqrt(g.value))
    assert exact == pytest.approx(1.8459, abs=5e-4)
    assert gain.gamma == pytest.approx(1.8496, abs=5e-4)


@needs_cvxpy
def test_against_004_eq_5_1():
    """(d): 004 prints Bf = A (T = 0.2 s, B = D = I), the dead-beat gain; ours is close to A and
    the dead-beat gain's worst-case gain is within 1e-3 of our gamma."""
    gain = solve_gain(T=0.2, dt=0.0012, process=1.0, measurement=1.0)
    A = gain.system.A
    assert np.abs(gain.Bf - A).max() < 0.1
    assert gain.gamma == pytest.approx(1.4897, abs=1e-3)
    deadbeat, _, _ = peak(np.zeros((4, 4)), gain.system.B1 - A @ gain.system.D1, np.eye(4))
    assert deadbeat == pytest.approx(gain.gamma, abs=1e-3)


@needs_cvxpy
def test_gamma_scales_with_the_weights_and_the_gain_does_not():
    one = solve_gain(**PAPER)
    cm = solve_gain(**{**PAPER, "process": 0.01, "measurement": 0.01})
    assert cm.gamma == pytest.approx(0.01 * one.gamma, rel=1e-6)
    np.testing.assert_allclose(cm.Bf, one.Bf, atol=1e-6)
    assert one.seconds > 0


@needs_cvxpy
def test_filter_steps_2_9_and_tracks_the_errors(gain):
    """X^_{k+1} = Af X^_k + Bf Y_k; without noise the estimate converges to X (A~ stable)."""
    f = HinfFilter(gain)
    s = gain.system
    X = np.array([5.0, -3.0, 0.5, 0.2])
    Y = s.C @ X
    assert np.array_equal(f.step(Y), gain.Bf @ Y)
    assert np.array_equal(f.x, gain.Bf @ Y)
    f.reset()
    assert not f.x.any()
    for _ in range(60):
        X_next = s.A @ X
        f.step(s.C @ X)
        X = X_next
    np.testing.assert_allclose(f.x, X, atol=1e-6 * np.abs(X).max())


def test_missing_cvxpy_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "cvxpy", None)
    with pytest.raises(MissingExtra) as e:
        solve_gain(**PAPER)
    line = "hinf needs cvxpy, which is not installed; pip install 'navtwin[lmi]'"
    assert str(e.value) == line
    assert isinstance(e.value, ModuleNotFoundError) and e.value.name == "cvxpy"
    assert missing_extra(e.value, None) == line  # any command prints it, exit status 2
