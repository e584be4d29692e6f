"""Models and filters: exact discretisation, Jacobians, gating, and statistical consistency."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.stats import chi2

from navtwin.host.filters import (ACCELERATION, ConstantAcceleration, ExtendedKalmanFilter, KalmanFilter, Linear,
                          Ranges, UnscentedKalmanFilter, position_fix)
from navtwin.host.filters.linalg import inverse, solve
from navtwin.host.wsn import AnchorLayout, tdoa_covariance

from ..helpers import OFFICE_ANCHORS

LAYOUT = AnchorLayout({k: (x, y, 2.4) for k, (x, y, _) in OFFICE_ANCHORS.items()}, tag_height=0.3)
MODEL = ConstantAcceleration(0.8)


def van_loan(q: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of continuous white jerk by Van Loan's matrix exponential (independent)."""
    A = np.kron(np.array([[0, 1, 0], [0, 0, 1], [0, 0, 0]], float), np.eye(2))
    G = np.kron(np.array([[0], [0], [1.0]]), np.eye(2))
    M = np.block([[-A, G @ G.T * q], [np.zeros((6, 6)), A.T]]) * dt
    E = expm(M)
    F = E[6:, 6:].T
    return F, F @ E[:6, 6:]


@pytest.mark.parametrize("dt", [0.01, 0.0137, 0.1, 1.0])
def test_motion_model_is_the_exact_discretisation(dt):
    F, Q = van_loan(0.8, dt)
    np.testing.assert_allclose(MODEL.F(dt), F, atol=1e-12)
    np.testing.assert_allclose(MODEL.Q(dt), Q, atol=1e-12, rtol=1e-9)
    # exact discretisations compose: two steps are one longer step
    a, b = 0.3 * dt, 0.7 * dt
    np.testing.assert_allclose(MODEL.F(b) @ MODEL.F(a), MODEL.F(dt), atol=1e-12)
    np.testing.assert_allclose(MODEL.F(b) @ MODEL.Q(a) @ MODEL.F(b).T + MODEL.Q(b), MODEL.Q(dt), atol=1e-14)


def numeric_jacobian(h, x, eps=1e-6):
    return np.column_stack([(h(x + e) - h(x - e)) / (2 * eps) for e in np.eye(len(x)) * eps])


@pytest.mark.parametrize("reference", [None, 1, 3])
def test_range_jacobians_match_finite_differences(reference):
    x = np.array([4.0, 2.5, 0.4, -0.2, 0.3, 0.1])
    meas = Ranges(LAYOUT, (1, 2, 3, 4), lags=(0.075, 0.05, 0.025, 0.0), reference=reference)
    np.testing.assert_allclose(meas.jacobian(x), numeric_jacobian(meas.h, x), atol=1e-8)
    assert meas.dim == (4 if reference is None else 3)
    hx, J = meas.linearize(x)  # the EKF's one-pass form: the same h and Jacobian
    np.testing.assert_allclose(hx, meas.h(x), rtol=1e-15)
    np.testing.assert_array_equal(J, meas.jacobian(x))


def test_ranges_use_the_lagged_position_and_work_on_sigma_stacks():
    x = np.array([4.0, 2.5, 0.4, -0.2, 0.3, 0.1])
    lag = 0.06
    p = x[:2] - lag * x[2:4] + lag**2 / 2 * x[4:6]
    (ax, ay, _), az = OFFICE_ANCHORS[3], 2.4  # anchor 3 of LAYOUT
    expected = np.sqrt((p[0] - ax) ** 2 + (p[1] - ay) ** 2 + (0.3 - az) ** 2)
    assert Ranges(LAYOUT, (3,), (lag,)).h(x)[0] == pytest.approx(expected, rel=1e-14)
    meas = Ranges(LAYOUT, (2, 4, 1), (0.01, 0.02, 0.03), reference=4)
    X = x + np.random.default_rng(1).normal(0, 0.5, (13, 6))
    np.testing.assert_allclose(meas.h(X), np.array([meas.h(row) for row in X]), rtol=1e-14)
    np.testing.assert_allclose(position_fix(lag).h(x), p, atol=1e-15)


def test_small_inverse_matches_numpy():
    rng = np.random.default_rng(2)
    for m in (1, 2, 3):
        A = rng.normal(size=(m, m))
        S = A @ A.T + np.eye(m)
        np.testing.assert_allclose(inverse(S), np.linalg.inv(S), rtol=1e-12)


def test_solve_gives_numpys_numbers_even_ill_conditioned():
    """solve calls the LAPACK routine np.linalg.solve and inv wrap: equal to the last bit, also
    for the nearly singular normal equations of anchors almost on a line (a WSN fix in a
    corridor), where another method's rounding shows."""
    rng = np.random.default_rng(3)
    solved = 0
    for k in range(200):
        J = rng.normal(size=(3, 2))
        if k % 2:
            J[:, 1] = J[:, 0] * (1 + 1e-7 * rng.normal()) + 1e-9 * rng.normal(size=3)
        N, b = J.T @ J, rng.normal(size=2)
        try:
            expected = np.linalg.solve(N, b)
        except np.linalg.LinAlgError:  # so singular that LAPACK met a zero pivot: so must we
            with pytest.raises(np.linalg.LinAlgError):
                solve(N, b)
            continue
        solved += 1
        np.testing.assert_array_equal(solve(N, b), expected)
        np.testing.assert_array_equal(solve(N, np.eye(2)), np.linalg.inv(N))
    assert solved > 100
    S = rng.normal(size=(4, 4))
    S = S @ S.T
    np.testing.assert_array_equal(inverse(S), np.linalg.inv(S))


@pytest.mark.parametrize("S", [np.zeros((1, 1)), np.ones((2, 2)), np.ones((3, 3))])
def test_singular_systems_raise_linalgerror(S):
    """What the estimator catches to re-initialise a filter, instead of going on with inf."""
    with pytest.raises(np.linalg.LinAlgError):
        inverse(S)
    with pytest.raises(np.linalg.LinAlgError):
        solve(S, np.ones(len(S)))


@pytest.mark.parametrize("cls", [KalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_gate_rejects_an_outlier_and_leaves_the_state_alone(cls):
    f = cls(np.array([5.0, 3.0, 0, 0, 0, 0]), np.eye(6) * 0.01, MODEL)
    x, P = f.x.copy(), f.P.copy()
    meas = position_fix() if cls is KalmanFilter else Ranges(LAYOUT, (1, 2))
    z0 = meas.h(x)
    R = np.eye(meas.dim) * 0.04
    inn = f.update(z0 + 3.0, R, meas, gate=chi2.ppf(0.9999, meas.dim))
    assert not inn.accepted
    assert np.array_equal(f.x, x) and np.array_equal(f.P, P)
    assert inn.nis == pytest.approx(inn.y @ np.linalg.solve(inn.S, inn.y), rel=1e-12)
    assert f.update(z0 + 0.05, R, meas, gate=chi2.ppf(0.9999, meas.dim)).accepted
    assert not np.array_equal(f.x, x)


def test_kf_refuses_a_nonlinear_measurement():
    with pytest.raises(TypeError, match="Linear"):
        KalmanFilter(np.zeros(6), np.eye(6), MODEL).update([5.0], [[0.1]], Ranges(LAYOUT, (1,)))


def test_unscented_transform_of_linear_maps_is_exact():
    """Why the UKF may predict and take the acceleration in closed form."""
    rng = np.random.default_rng(4)
    A = rng.normal(size=(6, 6))
    P = A @ A.T + np.eye(6)
    for alpha, beta, kappa in [(1.0, 2.0, None), (0.3, 2.0, 0.0), (1.0, 0.0, -3.0)]:
        f = UnscentedKalmanFilter(rng.normal(size=6), P, MODEL, alpha, beta, kappa)
        X = f.sigma_points()
        for H in (MODEL.F(0.01), ACCELERATION.H):
            Y = X @ H.T
            mean = f.Wm @ Y
            d = Y - mean
            np.testing.assert_allclose(mean, H @ f.x, atol=1e-12)
            np.testing.assert_allclose(d.T @ (f.Wc[:, None] * d), H @ P @ H.T, atol=1e-10)


@pytest.mark.parametrize("cls,wsn", [(KalmanFilter, "fix"), (ExtendedKalmanFilter, "toa"),
                                     (UnscentedKalmanFilter, "toa"), (ExtendedKalmanFilter, "tdoa"),
                                     (UnscentedKalmanFilter, "tdoa")])
def test_filters_are_consistent_when_truth_follows_their_model(cls, wsn):
    """NEES over Monte Carlo runs whose truth is drawn from the CA model itself: chi-square
    with 6 degrees of freedom per run, so the mean over runs lies in its 99.9 % interval."""
    rng = np.random.default_rng({"fix": 1, "toa": 2, "tdoa": 3}[wsn] + 10 * (cls is UnscentedKalmanFilter))
    runs, steps, dt, sigma = 60, 100, 0.1, 0.1
    q = 0.05
    model = ConstantAcceleration(q)
    F, Q = model.F(dt), model.Q(dt)
    L = np.linalg.cholesky(Q)
    P0 = np.diag([0.2, 0.2, 0.1, 0.1, 0.05, 0.05]) ** 2
    nees = []
    for _ in range(runs):
        truth = np.array([6.0, 3.5, 0.2, 0.1, 0.0, 0.0])
        f = cls(truth + rng.multivariate_normal(np.zeros(6), P0), P0, model)
        for _ in range(steps):
            truth = F @ truth + L @ rng.normal(size=6)
            f.predict(dt)
            f.update(truth[4:6] + rng.normal(0, 0.3, 2), 0.09 * np.eye(2), ACCELERATION)
            if wsn == "fix":
                f.update(truth[:2] + rng.normal(0, sigma, 2), sigma**2 * np.eye(2), position_fix())
            else:  # ranges from TWR; their differences share anchor 1's noise
                meas = Ranges(LAYOUT, (1, 2, 3, 4), reference=1 if wsn == "tdoa" else None)
                noise = rng.normal(0, sigma, 4)
                if wsn == "toa":
                    f.update(meas.h(truth) + noise, sigma**2 * np.eye(4), meas)
                else:
                    f.update(meas.h(truth) + noise[1:] - noise[0], tdoa_covariance(sigma, 3), meas)
        e = f.x - truth
        nees.append(e @ np.linalg.solve(f.P, e))
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * runs) / runs
    assert lo < np.mean(nees) < hi, (np.mean(nees), lo, hi)


def test_linear_measurement_shapes():
    m = Linear(np.hstack([np.eye(2), np.zeros((2, 4))]))
    assert m.dim == 2
    np.testing.assert_array_equal(m.h(np.arange(6.0)), [0.0, 1.0])
    np.testing.assert_array_equal(m.h(np.arange(12.0).reshape(2, 6)), [[0, 1], [6, 7]])
