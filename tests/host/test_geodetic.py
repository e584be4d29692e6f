"""003's geodetic strapdown (host.geodetic) and its error-state filter (host.filters.geodetic):
F_SINS against a numerical Jacobian of one strapdown step, the strapdown on a known geodetic
trajectory, and the filter's estimates of injected errors."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from navtwin.common.geodesy import meridian_radius, transverse_radius
from navtwin.host.filters.geodetic import NAV, GeodeticErrorFilter, error_model
from navtwin.host.geodetic import GeodeticStrapdown
from navtwin.host.sins import quat_from_euler, quat_to_dcm

from .navsynth import GeodeticRun, geodetic_north

GRAVITY = 9.7948


def _moving() -> GeodeticStrapdown:
    return GeodeticStrapdown(latitude_rad=math.radians(32.0), longitude_rad=math.radians(118.0),
                             height_m=30.0, velocity=(30.0, 40.0, 5.0), q=quat_from_euler(0.1, -0.2, 0.7),
                             local_gravity=GRAVITY)


def _inject(s: GeodeticStrapdown, dx) -> GeodeticStrapdown:
    """s with the errors dx (the filter's 15 states, computed minus true) put in."""
    d = -np.asarray(dx, float)
    s.correct(d[0:3], d[3:6], d[6:9], d[9:12], d[12:15])
    return s


def _errors(a: GeodeticStrapdown, b: GeodeticStrapdown) -> np.ndarray:
    """The 15 states of a against the truth b, read off the two strapdowns (not through F)."""
    E = np.eye(3) - np.array(quat_to_dcm(a.q)) @ np.array(quat_to_dcm(b.q)).T  # phi x
    phi = 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    return np.r_[np.subtract(a.v, b.v), phi, a.lat - b.lat, a.lon - b.lon, a.h - b.h,
                 np.subtract(b.accel_bias, a.accel_bias), np.subtract(b.gyro_bias, a.gyro_bias)]


def test_error_model_is_the_jacobian_of_a_strapdown_step():
    dt = 0.01
    # turning slowly: F takes C_b^n of the interval's start, the step its middle's (1e-4 apart)
    gyro, accel = (0.005, -0.003, 0.02), (0.7, -0.4, 9.9)
    # one perturbation per state: large enough to show over a step in doubles (64 m on
    # latitude), small enough that its square stays below the tolerance
    eps = np.r_[[1e-3] * 3, [1e-5] * 3, [1e-5] * 2, 10.0, [1e-4] * 3, [1e-6] * 3]
    truth = _moving()
    truth.step(0.0, gyro, accel)
    C = quat_to_dcm(truth.q)
    f_n = np.array(C) @ np.array(accel)
    F = error_model(truth.lat, truth.radii(), truth.v, f_n, C)
    ahead = truth.copy()
    ahead.step(dt, gyro, accel)
    J = np.empty((NAV, NAV))
    for k in range(NAV):
        dx = np.zeros(NAV)
        dx[k] = eps[k]
        s = _inject(truth.copy(), dx)
        s.step(dt, gyro, accel)
        J[:, k] = (_errors(s, ahead) - dx) / (eps[k] * dt)
    # one step of Phi = exp(F dt) is (I + F dt + (F dt)^2 / 2) to second order: J's reference
    G = F + F @ F * (dt / 2)
    # J's rounding: an ulp of each state's value over eps_k dt; entries far above it agree
    # within 1 % (the radii's change with latitude, which F leaves out as PSINS does, is 0.6 %
    # of dlambda's dL entry and dL's own), the rest within 1e3 roundings of zero or G
    size = np.r_[np.abs(truth.v), [1.0] * 3, abs(truth.lat), abs(truth.lon), abs(truth.h), [1.0] * 6]
    noise = np.outer(np.maximum(size, 1.0) * 2.2e-16, 1.0 / (eps * dt))
    err = np.abs(J - G)
    big = np.abs(G) > 1e4 * noise
    assert np.all(err[big] <= 1e-2 * np.abs(G[big])), np.argwhere(big & (err > 1e-2 * np.abs(G)))
    small_ok = err <= 1e3 * noise + 1e-2 * np.abs(G)
    assert np.all(small_ok[~big]), np.argwhere(~big & ~small_ok)


def _start_on(run: GeodeticRun, k: int = 0, **errors) -> GeodeticStrapdown:
    """A strapdown on the run's truth at sample k (level, heading north)."""
    return GeodeticStrapdown(latitude_rad=run.lat[k], longitude_rad=run.lon[k],
                             velocity=(0.0, run.v_north[k], 0.0), q=quat_from_euler(0.0, 0.0, math.pi / 2),
                             local_gravity=GRAVITY, **errors)


def test_free_strapdown_parked_then_driving_north_stays_on_the_truth():
    # a 10 s ramp: the trapezoid's error on its quadratic acceleration, -a'' dt^3 / 12 a step,
    # leaves 1e-6 m/s (a 2 s ramp 2.5e-5 m/s, 1 cm over the run)
    run = geodetic_north(park_s=60.0, duration_s=600.0, ramp_s=10.0)
    nav = _start_on(run)
    north, east, speed = [], [], []
    r_m, r_n = meridian_radius(run.lat[0]), transverse_radius(run.lat[0])
    for k in range(len(run.t)):
        nav.step(run.t[k] - run.t[k - 1] if k else 0.0, run.gyro[k], run.accel[k])
        north.append((nav.lat - run.lat[k]) * r_m)
        east.append((nav.lon - run.lon[k]) * r_n * math.cos(run.lat[k]))
        speed.append(nav.v[1] - run.v_north[k])
    # 535 m driven: the integration error, a millimetre (a strapdown that left out the
    # transport rate or the latitude's earth rate would be off by metres)
    assert max(map(abs, north)) < 2e-3 and max(map(abs, east)) < 1e-3, (min(north), max(east))
    assert max(map(abs, speed)) < 5e-6
    roll, pitch, yaw = nav.euler
    assert abs(roll) < 1e-6 and abs(pitch) < 1e-6 and abs(yaw - math.pi / 2) < 1e-6
    assert abs(nav.h) < 0.05


ARW, VRW = 0.5, 0.05  # deg/sqrt(h), m/s/sqrt(h): the synthetic IMU's white noise and the filter's
#: P0 sigmas (003 eq. 16's order): dV, phi (tilt, heading), dL dlambda as 1 m, dh, nabla, eps
SIGMA0 = np.r_[[0.02] * 3, [math.radians(0.05)] * 2, math.radians(1.0), [1.0] * 3,
               [1e-3 * GRAVITY] * 3, [math.radians(10.0) / 3600] * 3]


def _aided_run(seed: int, *, fixes: bool, heading: bool, duration_s: float = 300.0, heading_error=None):
    """The filter on the geodetic run with an IMU whose noise and biases it models: the start's
    errors and the biases drawn from P0 (or the heading error given), position fixes (1 m, 1 Hz,
    east and north) and/or a magnetometer heading (0.5 deg, 1 Hz). Returns the final errors
    (15, computed minus true, read off the strapdown and the truth) and P."""
    rng = np.random.default_rng(seed)
    dt = 0.02
    run = geodetic_north(park_s=20.0, duration_s=duration_s, ramp_s=10.0, dt=dt)
    r_m0, r_n0 = meridian_radius(run.lat[0]), transverse_radius(run.lat[0])
    scale = np.r_[[1.0] * 6, 1.0 / r_m0, 1.0 / (r_n0 * math.cos(run.lat[0])), [1.0] * 7]  # m -> rad
    sigma0 = SIGMA0 * scale
    x0 = rng.normal(0.0, sigma0)
    if heading_error is not None:
        x0[:] = 0.0
        x0[5] = heading_error
    nav = _inject(_start_on(run), np.r_[x0[:9], [0.0] * 6])
    gyro_w = math.radians(ARW) / 60.0 / math.sqrt(dt)
    accel_w = VRW / 60.0 / math.sqrt(dt)
    gyro = run.gyro + x0[12:15] + rng.normal(0.0, gyro_w, run.gyro.shape)
    accel = run.accel + x0[9:12] + rng.normal(0.0, accel_w, run.accel.shape)
    psd = np.r_[[(VRW / 60.0) ** 2] * 3, [(math.radians(ARW) / 60.0) ** 2] * 3, [0.0] * 10]
    P0 = np.diag(np.r_[sigma0, math.radians(0.01)] ** 2)
    kf = GeodeticErrorFilter(P0, psd)
    sigma_fix, sigma_heading = 1.0, math.radians(0.5)
    for k in range(len(run.t)):
        step = run.t[k] - run.t[k - 1] if k else 0.0
        nav.step(step, gyro[k], accel[k])
        if k:
            kf.predict(step, error_model(nav.lat, nav.radii(), nav.v, nav.f_n, nav.dcm()))
        if k % 50 or not k:
            continue
        rm, rn = nav.radii()
        if fixes:
            z = np.array([(nav.lon - run.lon[k]) * rn * math.cos(nav.lat), (nav.lat - run.lat[k]) * rm])
            H = np.zeros((2, 16))
            H[0, 7], H[1, 6] = rn * math.cos(nav.lat), rm
            kf.update(z + rng.normal(0.0, sigma_fix, 2), H, sigma_fix**2 * np.eye(2))
        if heading:
            C = nav.dcm()
            D = C[0][0] ** 2 + C[1][0] ** 2
            H = np.zeros((1, 16))
            H[0, 3:6] = C[0][0] * C[2][0] / D, C[1][0] * C[2][0] / D, -1.0
            H[0, 15] = -1.0
            z = nav.euler[2] - (math.pi / 2 + rng.normal(0.0, sigma_heading))
            kf.update(np.array([z]), H, np.array([[sigma_heading**2]]))
        dx = kf.take_nav()
        nav.correct(dx[0:3], dx[3:6], dx[6:9], dx[9:12], dx[12:15])
    truth = _start_on(run, len(run.t) - 1, accel_bias=x0[9:12], gyro_bias=x0[12:15])
    return _errors(nav, truth), kf.P[:NAV, :NAV], sigma0


def test_position_fixes_estimate_the_gyro_drift_consistently():
    """NEES over seeds of all 15 states (the unobservable ones too: their P must hold them),
    and the horizontal gyro drifts (10 deg/h at the start) estimated to a fraction."""
    seeds = range(8)
    nees, drift = [], []
    for seed in seeds:
        e, P, sigma0 = _aided_run(seed, fixes=True, heading=False)
        nees.append(e @ np.linalg.solve(P, e))
        drift.append(e[12:14] / sigma0[12:14])
    total = sum(nees)
    lo, hi = chi2.ppf([0.005, 0.995], NAV * len(seeds))
    assert lo < total < hi, (total, lo, hi, nees)
    assert np.sqrt(np.mean(np.square(drift))) < 0.3, drift


def test_magnetometer_heading_corrects_a_heading_error():
    err = math.radians(2.0)
    free, _, _ = _aided_run(0, fixes=False, heading=False, duration_s=80.0, heading_error=err)
    aided, P, _ = _aided_run(0, fixes=False, heading=True, duration_s=80.0, heading_error=err)
    # phi_U of +2 deg is a yaw 2 deg short; the magnetometer's 0.5 deg sigma over 79 updates
    assert free[5] == pytest.approx(err, abs=math.radians(0.2))  # the ARW: 0.08 deg, 1 sigma
    assert abs(aided[5]) < math.radians(0.2), math.degrees(aided[5])
    assert math.sqrt(P[5, 5]) < math.radians(0.2)
