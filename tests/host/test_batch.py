"""host.batch: N seeds stepped along a leading axis equal the per-filter classes stepped one
seed at a time (issue 23 item 1).

Each run draws a sequence of steps for N seeds from the real models (the estimator's
constant-acceleration KF with its acceleration and lagged-fix measurements; the 11-state
error-state filter with per-seed specific force, fixes and ranges with NLOS states): predicts
with a shared or a per-seed dt, gated updates with outliers that the gate rejects, and seeds
left out of steps. The same steps go through KalmanFilter / ErrorStateFilter per seed. Each
seed's x and P agree to 1e-12 relative to its P's largest entry, and with numpy handing each
seed's products to the same BLAS routines they are bit-identical (asserted apart, so a BLAS
that rounds a stacked product differently shows as that alone). The KF is also checked
against filterpy's KalmanFilter. ``navtwin bench batch``: its figures' shape, not its speed.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter as FpKF

from navtwin.host.batch import BatchErrorStateFilter, BatchKalmanFilter
from navtwin.host.batch.bench import GOAL, ONE_THREAD
from navtwin.host.batch.innovation import projected
from navtwin.host.batch.linalg import STACKED_UP_TO, inverse, mv, selection, solve_each
from navtwin.host.batch.model import hx
from navtwin.host.filters import ACCELERATION, ConstantAcceleration, KalmanFilter, Ranges, position_fix
from navtwin.host.filters.errorstate import NAV, ErrorStateFilter
from navtwin.host.wsn import chi2_gate

from .test_crosscheck import LAYOUT, events

MODEL = ConstantAcceleration(0.5)
RTOL = 1e-12
SIZES = (1, 7, 64)
GYRO_PSD = (math.radians(0.3) / 60.0) ** 2  # 0.3 deg/sqrt(h), 0.05 m/s/sqrt(h)
ACCEL_PSD = (0.05 / 60.0) ** 2
EXTRA = 4  # one NLOS random walk per office anchor: the 11-state filter


def spd(rng, sigmas) -> np.ndarray:
    """A dense covariance with standard deviations about *sigmas* (correlated states)."""
    n = len(sigmas)
    L = np.diag(sigmas) @ (np.eye(n) + 0.3 * np.tril(rng.normal(size=(n, n)), -1))
    return L @ L.T


def outliers(rng, n, m, sigma):
    """Measurement noise for n seeds, a fifth of them 100 sigma off (the gate rejects them)."""
    e = rng.normal(0.0, sigma, (n, m))
    e[rng.random(n) < 0.2] *= 100.0
    return e


def active_mask(rng, n):
    """None (all seeds) a third of the time, else about 80 % of them."""
    return None if rng.random() < 1 / 3 else rng.random(n) < 0.8


def chosen(active, n):
    return range(n) if active is None else np.flatnonzero(active)


def kf_run(n: int, seed: int = 23, steps: int = 60):
    """The batch KF and KF per seed through the same random steps; counts of what happened."""
    rng = np.random.default_rng(seed)
    x0 = np.column_stack((rng.uniform(0, 12, (n, 2)), rng.normal(0, 0.3, (n, 4))))
    P0 = np.stack([spd(rng, [0.3, 0.3, 0.05, 0.05, 0.2, 0.2]) for _ in range(n)])
    batch = BatchKalmanFilter(x0, P0, MODEL)
    alone = [KalmanFilter(x0[s], P0[s], MODEL) for s in range(n)]
    # (batch innovation, seed, the seed's alone); (batch feedback, the seed's alone)
    seen = {"left_out": 0, "innovations": [], "feedback": []}
    for _ in range(steps):
        active = active_mask(rng, n)
        seen["left_out"] += 0 if active is None else int(n - active.sum())
        kind = rng.integers(4)
        if kind == 0:  # predict, one dt
            dt = float(rng.choice([0.01, 0.0099, 0.025]))
            batch.predict(dt, active)
            for s in chosen(active, n):
                alone[s].predict(dt)
        elif kind == 1:  # predict, a dt per seed (the host clocks' rate estimates differ)
            dt = rng.choice([0.01, 0.0099, 0.0101], n)
            batch.predict(dt, active)
            for s in chosen(active, n):
                alone[s].predict(dt[s])
        else:
            meas = ACCELERATION if kind == 2 else position_fix(float(rng.uniform(0, 0.08)))
            z = np.array([meas.H @ f.x for f in alone]) + outliers(rng, n, 2, 0.3)
            R = (0.09 * np.eye(2) if rng.random() < 0.5
                 else np.stack([spd(rng, [0.3, 0.3]) for _ in range(n)]))
            gate = chi2_gate(2, 0.9999) if rng.random() < 0.8 else None
            inn = batch.update(z, R, meas, gate, active)
            for s in chosen(active, n):
                one = alone[s].update(z[s], R if R.ndim == 2 else R[s], meas, gate)
                seen["innovations"].append((inn, s, one))
            if active is not None:  # a seed left out has no innovation
                assert np.isnan(inn.nis[~active]).all() and not inn.accepted[~active].any()
    return batch, alone, seen


def es_run(n: int, seed: int = 23, steps: int = 80):
    """The batch error-state filter and ErrorStateFilter per seed through the same steps."""
    rng = np.random.default_rng(seed)
    dim = NAV + EXTRA
    P0 = np.stack([spd(rng, [0.3, 0.3, 0.1, 0.1, 0.03, 0.03, 0.05, 0.2, 0.2, 0.2, 0.2])
                   for _ in range(n)])
    kw = dict(gyro_psd=GYRO_PSD, accel_psd=ACCEL_PSD, extra=EXTRA, extra_psd=0.01)
    batch = BatchErrorStateFilter(P0, **kw)
    alone = [ErrorStateFilter(P0[s], **kw) for s in range(n)]
    # (batch innovation, seed, the seed's alone); (batch feedback, the seed's alone)
    seen = {"left_out": 0, "innovations": [], "feedback": []}
    for _ in range(steps):
        active = active_mask(rng, n)
        seen["left_out"] += 0 if active is None else int(n - active.sum())
        kind = rng.integers(6)
        if kind < 3:  # predict: each seed's own specific force (its vehicle's manoeuvre)
            f_n = np.array([0.1, -0.05, 9.7952]) + rng.normal(0, 0.5, (n, 3))
            dt = 0.01 if kind < 2 else rng.choice([0.01, 0.0099], n)
            batch.predict(dt, f_n, active)
            for s in chosen(active, n):
                alone[s].predict(dt if np.ndim(dt) == 0 else dt[s], f_n[s])
            continue
        if kind == 5:  # the feedback into each seed's strapdown (closed loop)
            dx = batch.take_nav(active)
            seen["feedback"] += [(dx[s], alone[s].take_nav()) for s in chosen(active, n)]
            continue
        if kind == 3:  # a lc fix: H = [I 0]
            H = np.zeros((2, dim))
            H[0, 0] = H[1, 1] = 1.0
        else:  # tc: one or three ranges, each with its anchor's NLOS state
            m = int(rng.choice([1, 3]))
            u = rng.normal(size=(m, 2))
            H = np.zeros((m, dim))
            H[:, :2] = u / np.linalg.norm(u, axis=1)[:, None]
            H[np.arange(m), NAV + rng.choice(EXTRA, m, replace=False)] = 1.0
        m = len(H)
        z = outliers(rng, n, m, 0.3)
        R = 0.09 * np.eye(m)
        gate = chi2_gate(m, 0.9999)
        inn = batch.update(z, H, R, gate, active)
        for s in chosen(active, n):
            seen["innovations"].append((inn, s, alone[s].update(z[s], H, R, gate)))
    return batch, alone, seen


RUNS = {"kf": kf_run, "errorstate": es_run}


@pytest.fixture(scope="module", params=[(name, n) for name in RUNS for n in SIZES],
                ids=lambda p: f"{p[0]}-N{p[1]}")
def run(request):
    name, n = request.param
    return RUNS[name](n)


def test_each_seed_equals_its_filter_alone_to_1e_12(run):
    batch, alone, seen = run
    n = len(alone)
    accepted = [one.accepted for _, _, one in seen["innovations"]]
    # the steps did what they should: updates taken and gated out, seeds left out
    assert sum(accepted) > 10 and not all(accepted) and (n == 1 or seen["left_out"] > 0)
    for inn, s, one in seen["innovations"]:  # the same gate decisions on the same NIS
        assert inn.accepted[s] == one.accepted
        assert inn.nis[s] == pytest.approx(one.nis, rel=RTOL)
        np.testing.assert_allclose(inn.S[s], one.S, rtol=RTOL)
    for s, f in enumerate(alone):
        scale = np.abs(f.P).max()
        np.testing.assert_allclose(batch.P[s], f.P, rtol=0, atol=RTOL * scale)
        np.testing.assert_allclose(batch.x[s], f.x, rtol=RTOL, atol=RTOL * math.sqrt(scale))
    for mine, theirs in seen["feedback"]:
        np.testing.assert_allclose(mine, theirs, rtol=RTOL, atol=1e-15)


def test_each_seed_is_bit_identical_to_its_filter_alone(run):
    """The products are the per-filter ones, by the same BLAS routines: no rounding apart."""
    batch, alone, seen = run
    for inn, s, one in seen["innovations"]:
        assert inn.nis[s] == one.nis
        np.testing.assert_array_equal(inn.S[s], one.S)
    for mine, theirs in seen["feedback"]:
        np.testing.assert_array_equal(mine, theirs)
    np.testing.assert_array_equal(batch.P, np.stack([f.P for f in alone]))
    np.testing.assert_array_equal(batch.x, np.stack([f.x for f in alone]))


def test_a_seed_left_out_keeps_its_state_and_the_others_move():
    rng = np.random.default_rng(1)
    x0 = rng.normal(size=(3, 6))
    P0 = np.stack([spd(rng, [0.3] * 6) for _ in range(3)])
    f = BatchKalmanFilter(x0, P0, MODEL)
    active = np.array([True, False, True])
    f.predict(0.01, active)
    inn = f.update(np.zeros((3, 2)), np.eye(2), ACCELERATION, None, active)
    np.testing.assert_array_equal(f.x[1], x0[1])
    np.testing.assert_array_equal(f.P[1], P0[1])
    assert not np.isclose(f.P[[0, 2]], P0[[0, 2]]).all(axis=(1, 2)).any()
    assert inn.accepted.tolist() == [True, False, True] and np.isnan(inn.y[1]).all()


def test_kf_matches_filterpy_for_each_seed():
    """Five seeds of test_crosscheck's office ellipse (a lagged fix every 100 ms, acceleration
    every 10 ms; the schedule is the seeds', the noise each its own), beside filterpy."""
    seeds = range(5)
    runs = [events(3.0, "fix", seed=s) for s in seeds]
    X0 = np.array([6.0, 1.8, 0.0, 0.0, 0.0, 0.0])
    P0 = np.diag([0.3, 0.3, 0.05, 0.05, 0.2, 0.2]) ** 2
    batch = BatchKalmanFilter(np.tile(X0, (5, 1)), np.tile(P0, (5, 1, 1)), MODEL)
    fps = []
    for _ in seeds:
        fp = FpKF(dim_x=6, dim_z=2)
        fp.x, fp.P = X0.copy(), P0.copy()
        fps.append(fp)
    for steps in zip(*runs):
        dt, _, R, meas = steps[0]
        batch.predict(dt)
        batch.update(np.stack([z for _, z, _, _ in steps]), R, meas)
        for fp, (_, z, _, _) in zip(fps, steps):
            fp.predict(F=MODEL.F(dt), Q=MODEL.Q(dt))
            fp.update(z, R=R, H=meas.H)
    assert sum(m is not ACCELERATION for *_, m in runs[0]) >= 25  # lagged fixes among them
    for s, fp in enumerate(fps):
        scale = np.abs(fp.P).max()
        np.testing.assert_allclose(batch.P[s], fp.P, rtol=0, atol=RTOL * scale)
        np.testing.assert_allclose(batch.x[s], fp.x, rtol=0, atol=RTOL * 10)


def test_the_inverse_is_the_per_filter_one_and_names_singular_seeds():
    from navtwin.host.filters.linalg import inverse as one

    rng = np.random.default_rng(4)
    for m in (1, 2, 3):
        S = np.stack([spd(rng, [1.0] * m) for _ in range(9)])
        np.testing.assert_array_equal(inverse(S), np.stack([one(s) for s in S]))
        S[[2, 5]] = 0.0
        with pytest.raises(np.linalg.LinAlgError, match=r"singular innovation covariance at "
                                                        r"seeds \[2, 5\]; leave them out"):
            inverse(S)


def test_a_shared_h_that_picks_states_is_taken_bit_for_bit_as_multiplied():
    """selection names the columns a Motion product's H picks (rows of the identity) and
    nothing for any other H; the entries taken are the BLAS products' numbers."""
    from navtwin.host.inertial import STATIONARY

    assert selection(ACCELERATION.H).tolist() == [4, 5]
    assert selection(STATIONARY.H).tolist() == [2, 3, 4, 5]
    for H in (position_fix(0.1).H, 2.0 * ACCELERATION.H, ACCELERATION.H[:, ::-1] + ACCELERATION.H,
              np.stack([ACCELERATION.H] * 3)):
        assert selection(H) is None
    rng = np.random.default_rng(5)
    P = np.stack([spd(rng, [10.0 ** k for k in range(-3, 3)]) for _ in range(40)])
    x = rng.normal(size=(40, 6)) * 1e3
    for H in (ACCELERATION.H, STATIONARY.H):
        m = len(H)
        R = np.stack([spd(rng, [1.0] * m) for _ in range(40)])
        for taken, multiplied in zip(projected(P, H, R, selection(H)), projected(P, H, R, None)):
            assert taken.flags.c_contiguous
            np.testing.assert_array_equal(taken, multiplied)
        np.testing.assert_array_equal(hx(H, x), mv(H, x))


@pytest.mark.parametrize("m", range(2, STACKED_UP_TO + 3))
def test_the_stacked_solves_are_the_per_filter_gesv_bit_for_bit(m):
    """solve_each (the stacked LAPACK call up to STACKED_UP_TO, seed by seed past it) gives
    each seed host.filters.linalg.solve's numbers, on SPD systems over 12 decades and general
    ones, a vector or a matrix on the right, and names the singular seeds: the installed
    numpy's LAPACK build must round as scipy's for the sizes it is trusted with."""
    from navtwin.host.filters.linalg import solve as one

    rng = np.random.default_rng(m)
    A = rng.normal(size=(2000, m, m))
    A[::2] = np.matmul(A[::2], np.swapaxes(A[::2], 1, 2)) + 0.01 * np.eye(m)
    A *= 10.0 ** rng.uniform(-6, 6, (len(A), 1, 1))
    for B in (rng.normal(size=(len(A), m)), np.broadcast_to(np.eye(m), A.shape)):
        X, singular = solve_each(A, B)
        assert not singular.any()
        assert all(np.array_equal(X[k], one(A[k], B[k])) for k in range(len(A)))
    A[[3, 7]] = 0.0
    X, singular = solve_each(A[:10], B[:10])
    assert np.flatnonzero(singular).tolist() == [3, 7]
    assert all(np.array_equal(X[k], one(A[k], B[k])) for k in (0, 1, 2, 4, 5, 6, 8, 9))


@pytest.mark.parametrize("make, message", [
    (lambda: BatchKalmanFilter(np.zeros(6), np.eye(6), MODEL), r"x must be \(N, n\) and P"),
    (lambda: BatchKalmanFilter(np.zeros((3, 6)), np.zeros((3, 6, 6)), MODEL)
     .predict(0.01, np.ones(2, bool)), "active must be a boolean mask of the 3 seeds"),
    (lambda: BatchKalmanFilter(np.zeros((3, 6)), np.tile(np.eye(6), (3, 1, 1)), MODEL)
     .update(np.zeros((3, 2)), np.zeros((2, 2, 2)), ACCELERATION), r"R must have 2 axes \(shared\)"),
    (lambda: BatchErrorStateFilter(np.zeros((3, 9, 9)), gyro_psd=1.0, accel_psd=1.0, extra=4),
     r"P0 must be \(N, 11, 11\) for 4 extra states"),
])
def test_a_misshapen_input_is_one_line_naming_the_fix(make, message):
    with pytest.raises(ValueError, match=message) as e:
        make()
    assert "\n" not in str(e.value)


def test_the_kf_takes_linear_measurements_only():
    f = BatchKalmanFilter(np.zeros((2, 6)), np.tile(np.eye(6), (2, 1, 1)), MODEL)
    with pytest.raises(TypeError, match="needs a Linear measurement, got Ranges"):
        f.update(np.zeros((2, 1)), np.eye(1), Ranges(LAYOUT, (1,)))


def test_bench_batch_times_both_paths_at_each_n_in_a_one_thread_child(capsys):
    """The figures' shape and arithmetic (not the machine's speed): each N's ratio is its
    rates' quotient, and the child saw the one-thread settings before numpy loaded."""
    from navtwin.cli.main import main

    assert main(["bench", "batch", "--quick", "--sizes", "1,3", "--repeats", "1",
                 "--seconds", "0.001"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["threads_env"] == dict.fromkeys(ONE_THREAD, "1")
    for step in ("kf_step", "errorstate_predict"):
        by_n = out[step]["by_n"]
        assert list(by_n) == ["1", "3"]
        for r in by_n.values():
            assert r["batch_steps_per_s"] > 0 and r["per_filter_steps_per_s"] > 0
            assert r["ratio"] == pytest.approx(r["batch_steps_per_s"] / r["per_filter_steps_per_s"],
                                               abs=0.01)
        best = out[step]["best_n"]
        assert out[step]["goal_met"] == (by_n[str(best)]["batch_steps_per_s"] >= GOAL)


@pytest.mark.parametrize("argv, line", [
    (["--sizes", "0,16"], "--sizes must be counts 1..65536, comma-separated"),
    (["--repeats", "0"], "--repeats must be in [1, 100]"),
])
def test_bench_batch_refuses_a_bad_setting_in_one_line(capsys, argv, line):
    from navtwin.cli.main import main

    try:
        code = main(["bench", "batch", *argv])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and line in err
