"""Our KF, EKF and UKF against filterpy 2.0.0 and pykalman on identical inputs, step by step.

Inputs: a vehicle on an ellipse in the office, measured at the IMU rate (nav-frame
acceleration), per exchange (one range, anchors in turn every 25 ms), per cycle (the TDOA set
of 000 eqs. 12-13 with lags, or a lagged position fix). Every event is predict(dt) then one
update, the pattern all three libraries share. Tolerance 1e-9 on x and P (fusion-facts 1.4).
"""
from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter as FpEKF
from filterpy.kalman import KalmanFilter as FpKF
from filterpy.kalman import MerweScaledSigmaPoints
from filterpy.kalman import UnscentedKalmanFilter as FpUKF
from pykalman import AdditiveUnscentedKalmanFilter, KalmanFilter as PkKF

from navtwin.host.filters import (ACCELERATION, ConstantAcceleration, ExtendedKalmanFilter, KalmanFilter,
                          Ranges, UnscentedKalmanFilter, position_fix)
from navtwin.host.wsn import AnchorLayout, tdoa_covariance

from ..helpers import OFFICE_ANCHORS
from .navsynth import ellipse

ATOL = 1e-9
MODEL = ConstantAcceleration(0.5)
LAYOUT = AnchorLayout({k: (x, y, 2.0) for k, (x, y, _) in OFFICE_ANCHORS.items()}, tag_height=0.3)
X0 = np.array([6.0, 1.8, 0.0, 0.0, 0.0, 0.0])
P0 = np.diag([0.3, 0.3, 0.05, 0.05, 0.2, 0.2]) ** 2
SIGMA_R = 0.3


def events(seconds: float, wsn: str, seed: int = 7):
    """[(dt, z, R, measurement)]: acceleration every 10 ms, WSN every 25 ms (TOA) or 100 ms."""
    rng = np.random.default_rng(seed)
    truth = lambda t: ellipse(np.atleast_1d(t), omega=0.15, t_start=0.5, ramp=1.0)
    times = sorted({round(k * 0.01, 6) for k in range(1, int(seconds / 0.01))}
                   | {round(0.0037 + k * 0.025, 6) for k in range(int(seconds / 0.025))})
    out, last, ids = [], 0.0, LAYOUT.ids
    for t in times:
        if abs(t / 0.01 - round(t / 0.01)) < 1e-6:  # an IMU sample
            z = truth(t).a[0] + rng.normal(0, 0.3, 2)
            out.append((t - last, z, 0.09 * np.eye(2), ACCELERATION))
        else:
            slot = int(round((t - 0.0037) / 0.025))
            if wsn == "toa":
                a = ids[slot % 4]
                p = truth(t).p[0]
                r = LAYOUT.ranges(p[None], LAYOUT.index([a]))[0] + rng.normal(0, SIGMA_R)
                out.append((t - last, np.array([r]), np.array([[SIGMA_R**2]]), Ranges(LAYOUT, (a,))))
            elif slot % 4 == 3:  # the cycle closes with its fourth exchange
                ts = t - 0.025 * np.arange(3, -1, -1)
                tr = truth(ts)
                r = np.array([LAYOUT.ranges(tr.p[k][None], LAYOUT.index([a]))[0] for k, a in enumerate(ids)])
                r += rng.normal(0, SIGMA_R, 4)
                lags = t - ts
                if wsn == "tdoa":
                    meas = Ranges(LAYOUT, ids, lags, reference=1)
                    out.append((t - last, r[1:] - r[0], tdoa_covariance(SIGMA_R, 3), meas))
                else:  # a position fix at the cycle's mean time
                    lag = float(np.mean(lags))
                    z = truth(t - lag).p[0] + rng.normal(0, 0.2, 2)
                    out.append((t - last, z, 0.04 * np.eye(2), position_fix(lag)))
            else:
                continue
        last = t
    return out


def run_pair(ours, step_theirs, get_theirs, evs):
    """Both filters through *evs*: x and P agree within ATOL after every step. The steps are
    compared together at the end (a per-step assert_allclose was half of these tests' time)."""
    mine, theirs = [], []
    for dt, z, R, meas in evs:
        ours.predict(dt)
        ours.update(z, R, meas)
        step_theirs(dt, z, R, meas)
        x, P = get_theirs()
        mine.append(np.concatenate((ours.x, np.ravel(ours.P))))
        theirs.append(np.concatenate((np.ravel(x), np.ravel(P))))
    gap = np.abs(np.array(mine) - np.array(theirs))
    bad = np.flatnonzero(~(gap <= ATOL).all(axis=1))  # NaN is a difference too
    assert len(bad) == 0, f"step {bad[0]} of {len(evs)}: x, P differ by {np.nanmax(gap[bad[0]])}"
    return gap[:, :len(X0)].max()


def test_kf_matches_filterpy_kalmanfilter():
    fp = FpKF(dim_x=6, dim_z=2)
    fp.x, fp.P = X0.copy(), P0.copy()

    def step(dt, z, R, meas):
        fp.predict(F=MODEL.F(dt), Q=MODEL.Q(dt))
        fp.update(z, R=R, H=meas.H)

    evs = events(20.0, "fix")
    assert sum(m is not ACCELERATION for *_, m in evs) > 150  # lagged position fixes
    run_pair(KalmanFilter(X0, P0, MODEL), step, lambda: (fp.x, fp.P), evs)


def test_kf_matches_pykalman_filter_update():
    pk = PkKF()
    state = [X0.copy(), P0.copy()]

    def step(dt, z, R, meas):
        state[:] = pk.filter_update(state[0], state[1], observation=z, transition_matrix=MODEL.F(dt),
                                    transition_offset=np.zeros(6), transition_covariance=MODEL.Q(dt),
                                    observation_matrix=meas.H, observation_offset=np.zeros(len(z)),
                                    observation_covariance=R)

    run_pair(KalmanFilter(X0, P0, MODEL), step, lambda: tuple(state), events(10.0, "fix"))


@pytest.mark.parametrize("wsn", ["toa", "tdoa"])
def test_ekf_matches_filterpy_extendedkalmanfilter(wsn):
    fp = FpEKF(dim_x=6, dim_z=1)
    fp.x, fp.P = X0.copy(), P0.copy()

    def step(dt, z, R, meas):
        fp.F, fp.Q = MODEL.F(dt), MODEL.Q(dt)
        fp.predict()
        fp.update(z, HJacobian=meas.jacobian, Hx=meas.h, R=R)

    run_pair(ExtendedKalmanFilter(X0, P0, MODEL), step, lambda: (fp.x, fp.P), events(20.0, wsn))


def _filterpy_ukf(alpha, beta, kappa):
    points = MerweScaledSigmaPoints(6, alpha=alpha, beta=beta, kappa=kappa)
    fp = FpUKF(dim_x=6, dim_z=1, dt=0.01, hx=ACCELERATION.h, fx=lambda x, dt: MODEL.F(dt) @ x, points=points)
    fp.x, fp.P = X0.copy(), P0.copy()
    return fp, points


@pytest.mark.parametrize("wsn", ["toa", "tdoa"])
@pytest.mark.parametrize("alpha,beta,kappa", [(1.0, 2.0, -3.0), (0.5, 2.0, 0.0)])
def test_ukf_matches_filterpy_unscentedkalmanfilter(wsn, alpha, beta, kappa):
    fp, _ = _filterpy_ukf(alpha, beta, kappa)

    def step(dt, z, R, meas):
        fp.Q = MODEL.Q(dt)
        fp.predict(dt=dt)  # all through sigma points, then the 2.0.0 redraw
        fp.update(z, R=R, hx=meas.h)

    ours = UnscentedKalmanFilter(X0, P0, MODEL, alpha=alpha, beta=beta, kappa=kappa)
    evs = events(12.0, wsn)
    run_pair(ours, step, lambda: (fp.x, fp.P), evs)
    # The comparison can tell the filters apart: the EKF on the same ranges differs.
    ekf = ExtendedKalmanFilter(X0, P0, MODEL)
    for dt, z, R, meas in evs:
        ekf.predict(dt)
        ekf.update(z, R, meas)
    assert np.abs(ekf.x[:2] - ours.x[:2]).max() > 1e-6


def test_ukf_consecutive_updates_use_the_current_mean_and_covariance():
    """Two updates without a predict: ours redraws the points from the posterior of the
    first; filterpy does the same once its points are redrawn by hand."""
    fp, points = _filterpy_ukf(1.0, 2.0, -3.0)
    ours = UnscentedKalmanFilter(X0, P0, MODEL)
    evs = [e for e in events(6.0, "toa") if e[3] is not ACCELERATION]
    for (dt, z1, R1, m1), (_, z2, R2, m2) in zip(evs[::2], evs[1::2]):
        ours.predict(dt)
        fp.Q = MODEL.Q(dt)
        fp.predict(dt=dt)
        for z, R, m in ((z1, R1, m1), (z2, R2, m2)):
            ours.update(z, R, m)
            fp.update(z, R=R, hx=m.h)
            fp.sigmas_f = points.sigma_points(fp.x, fp.P)
            np.testing.assert_allclose(ours.x, fp.x, rtol=0, atol=ATOL)
            np.testing.assert_allclose(ours.P, fp.P, rtol=0, atol=ATOL)


@pytest.mark.parametrize("wsn", ["toa", "tdoa"])
def test_ukf_matches_pykalman_additive_ukf(wsn):
    """pykalman's additive UKF has alpha = 1, beta = 0, kappa = 3 - n built in."""
    pk = AdditiveUnscentedKalmanFilter()
    state = [X0.copy(), P0.copy()]

    def step(dt, z, R, meas):
        F = MODEL.F(dt)
        state[:] = pk.filter_update(state[0], state[1], observation=z, transition_function=lambda x: F @ x,
                                    transition_covariance=MODEL.Q(dt), observation_function=meas.h,
                                    observation_covariance=R)

    ours = UnscentedKalmanFilter(X0, P0, MODEL, alpha=1.0, beta=0.0, kappa=3.0 - 6)
    run_pair(ours, step, lambda: tuple(state), events(5.0, wsn))
