"""Microseconds per step of each filter, the strapdown and the whole estimator.

    python -m navtwin.cli.filters_bench [--steps N] [--json]

A step is what the estimator does per measurement: predict over the interval, then one
update. ``sins`` is one strapdown step. 001's error-state tracks: ``lc/imu``, ``tc/imu``,
``fatci/imu`` one IMU sample through the track (its strapdown step and predict), and
``lc/fix``, ``tc/range``, ``fatci/range`` that plus one update. ``estimator/imu`` is one
100 Hz IMU sample through the estimator with the default tracks on (``estimator/imu all``:
every built-in track, 001's too), including its share of the 40 exchanges per second (so
1e6 / that number is the estimator's speed in multiples of real time). pytest-benchmark
runs the same cases: ``pytest tests/host/test_filters_bench.py --benchmark-only``.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from . import tracks
from .estimator import Estimator, EstimatorConfig
from .filters import (ACCELERATION, ConstantAcceleration, ExtendedKalmanFilter, KalmanFilter, Ranges,
                      UnscentedKalmanFilter, position_fix)
from .measurements import Exchange, Fix, ImuSample, Range
from .sins import Strapdown, quat_from_euler
from .wsn import AnchorLayout, tdoa_covariance

DT = 0.01
X0 = np.array([6.0, 1.8, 0.3, 0.1, 0.05, -0.02])
P0 = np.diag([0.2, 0.2, 0.05, 0.05, 0.1, 0.1]) ** 2


def cases() -> dict[str, Callable[[], object]]:
    """name -> a callable doing one step on fresh state (deterministic inputs)."""
    model = ConstantAcceleration(0.5)
    layout = AnchorLayout(EstimatorConfig().anchors)
    z_acc, r_acc = np.array([0.05, -0.02]), 1.5**2 * np.eye(2)
    toa = Ranges(layout, (2,))
    z_toa, r_toa = toa.h(X0) + 0.1, np.array([[0.16]])
    tdoa = Ranges(layout, (1, 2, 3, 4), (0.075, 0.05, 0.025, 0.0), reference=1)
    z_tdoa, r_tdoa = tdoa.h(X0) + 0.1, tdoa_covariance(0.4, 3)
    fix = position_fix(0.04)
    z_fix, r_fix = X0[:2] + 0.1, 0.1 * np.eye(2)

    def step(cls, z, R, meas, **kw):
        f = cls(X0, P0, model, **kw)

        def one():
            f.predict(DT)
            f.update(z, R, meas)
        return one

    out = {
        "kf/accel": step(KalmanFilter, z_acc, r_acc, ACCELERATION),
        "kf/fix": step(KalmanFilter, z_fix, r_fix, fix),
        "ekf/accel": step(ExtendedKalmanFilter, z_acc, r_acc, ACCELERATION),
        "ekf/range": step(ExtendedKalmanFilter, z_toa, r_toa, toa),
        "ekf/tdoa": step(ExtendedKalmanFilter, z_tdoa, r_tdoa, tdoa),
        "ukf/accel": step(UnscentedKalmanFilter, z_acc, r_acc, ACCELERATION),
        "ukf/range": step(UnscentedKalmanFilter, z_toa, r_toa, toa),
        "ukf/tdoa": step(UnscentedKalmanFilter, z_tdoa, r_tdoa, tdoa),
    }
    sins = Strapdown(position=(6.0, 1.8), q=quat_from_euler(0.0, 0.0, 0.3), latitude_deg=34.316, gravity=9.7952)
    gyro, accel = (0.001, -0.002, 0.1), (0.05, 0.04, 9.7952)  # floats, as the estimator passes them
    out["sins"] = lambda: sins.step(DT, gyro, accel)
    out["estimator/imu"] = _estimator_step()
    out["estimator/imu all"] = _estimator_step(tracks.BUILT_IN)
    out.update(_error_state_steps())
    return out


def _error_state_steps() -> dict[str, Callable[[], object]]:
    """001's tracks: one IMU sample (their strapdown step and predict over 10 ms) and one
    update (lc: a fix, tc and fatci: a range), past the alignment of a parked vehicle."""
    out = {}
    p = np.array([6.0, 1.8])
    for name, kind in (("lc", "fix"), ("tc", "range"), ("fatci", "range")):
        cfg = EstimatorConfig(alignment_s=0.5, filters=(name,))
        est = Estimator(cfg)
        for k in range(60):  # through the alignment
            est.feed(ImuSample(k * DT, (0.0, 0.0, 0.0), (0.0, 0.0, 9.7952)))
        track = est.tracks[0]
        state = {"t": 60 * DT}
        meas = Ranges(est.layout, (2,))
        z = est.layout.ranges(p[None], meas.idx) + 0.1
        fix = Fix(0.0, p + 0.1, 0.04 * np.eye(2), (1, 2, 3, 4), 1.0)

        def imu(track=track, state=state):
            state["t"] += DT
            t = state["t"]
            track.imu(ImuSample(t, (0.001, -0.002, 0.0), (0.05, 0.04, 9.7952)))
            return t

        def update(track=track, imu=imu, z=z, meas=meas, fix=fix, kind=kind):
            t = imu()
            if kind == "fix":
                track.fix(Fix(t, fix.p, fix.cov, fix.anchors, fix.chi2))
            else:
                track.range(Range(t, z, np.array([[0.16]]), meas))
        out[f"{name}/imu"] = imu
        out[f"{name}/{kind}"] = update
    return out


def _estimator_step(filters: tuple[str, ...] = tracks.DEFAULT) -> Callable[[], object]:
    """One IMU sample (and 0.4 exchanges) of a parked vehicle through the default five
    tracks (or *filters*)."""
    cfg = EstimatorConfig(alignment_s=0.5, filters=filters)
    est = Estimator(cfg)
    rng = np.random.default_rng(0)
    layout = AnchorLayout(cfg.anchors)
    ranges = layout.ranges(np.array([[6.0, 1.8]]), np.arange(4))
    state = {"k": 0}

    def one():
        k = state["k"]
        state["k"] = k + 1
        t = k * DT
        est.feed(ImuSample(t, rng.normal(0, 0.01, 3), np.array([0.0, 0.0, 9.7952]) + rng.normal(0, 0.3, 3)))
        if k % 10 in (0, 2, 5, 7):  # four exchanges per 100 ms
            a = (k // 10 * 4 + (0, 2, 5, 7).index(k % 10)) % 4
            est.feed(Exchange(t + 0.005, a + 1, ranges[a] + rng.normal(0, 0.3), -60, 0x0F))
    for _ in range(100):  # through the alignment first
        one()
    return one


def measure(steps: int = 2000, repeats: int = 5) -> dict[str, float]:
    """Median over *repeats* of the mean microseconds per step of each case."""
    result = {}
    for name, one in cases().items():
        runs = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(steps):
                one()
            runs.append((time.perf_counter() - t0) / steps * 1e6)
        result[name] = float(np.median(runs))
    return result
