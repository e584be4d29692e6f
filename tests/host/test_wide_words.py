"""The host reads the wide sample frames (type 03) with no setting, and through their 32-bit
words sees what the 14-bit ADIS16350 words of the same run hide: 003's navigation grade.

A parked ``rssi-centroid`` (32 N, level, facing north) for 60 s, its SINS bytes decoded by
the host's pipeline: the mean gyro output equals the earth rate W (0, cos L, sin L) (n frame,
x east, y north, z up; rotated into the body) within the error the ``paper003`` grade
predicts, and the mean specific force equals local gravity within the grade's bias. The same
run (same seed, same draws) through the 14-bit words at +-75 deg/s reads 0 on every gyro word
and one constant word on the level accelerometers: the grade is not in them."""
import dataclasses
import math

import numpy as np
import pytest

from navtwin.common.earth import EARTH_RATE
from navtwin.emulator.allan import parked
from navtwin.emulator.bias import FLICKER_TAUS_S, flicker_term_variance
from navtwin.emulator.imu import body_from_nav, deg_h, ug
from navtwin.emulator.trajectory import Trajectory
from navtwin.emulator.world import World
from navtwin.host.pipeline import Pipeline
from navtwin.protocols import adis16488, ports

from ..helpers import OFFICE
from .fake_estimator import RecordingEstimator

SECONDS = 60.0
TAPS = {"grade": "paper003", "filter_taps": 16}


def host_samples(imu: dict, seed: int = 3):
    """The scenario parked for SECONDS with ``[imu]`` *imu* (no magnetometer: samples only),
    its SINS line fed to the host's pipeline (the office's host config: its gyro range is
    not the wide words'); the
    (N, 3) gyro and accelerometer outputs the estimator was given, and the scenario."""
    sc = dataclasses.replace(parked(SECONDS, imu, base="rssi-centroid"), magnetometer=None)
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=(ports.SINS.name,))
    for e in World(sc, seed).advance(round(SECONDS * 1e9)):
        if e.port == ports.SINS.name:
            pipe.feed(e.port, e.data, e.t_ns)
    calls = [c for c in est.calls if c[0] == "imu"]
    assert len(calls) >= SECONDS * 100 - 2 and all(c[4] for c in calls)  # every sample, ND set
    return np.array([c[2] for c in calls]), np.array([c[3] for c in calls]), sc


def truth(sc):
    """Error-free gyro (rad/s) and specific force (m/s^2) of the parked vehicle, body axes."""
    k = Trajectory(sc.trajectory, sc.tag.z).kinematics(np.array([0], dtype=np.int64))
    c_bn = body_from_nav(k.roll, k.pitch, k.yaw)[0]
    lat = math.radians(sc.site.latitude_deg)
    north = math.radians(sc.area.x_azimuth_deg)
    w_n = EARTH_RATE * np.array([math.cos(lat) * math.cos(north), math.cos(lat) * math.sin(north),
                                 math.sin(lat)])
    return c_bn @ w_n, c_bn @ np.array([0.0, 0.0, sc.site.local_gravity])


def predicted_sigma(bias: float, floor: float, white: float, lsb: float, n: int) -> float:
    """1 sigma of a SECONDS mean of one axis: the power-on bias, the flicker bias (all its
    terms' variance: an upper bound on its mean's), white noise N / sqrt(T), rounding."""
    return math.sqrt(bias ** 2 + len(FLICKER_TAUS_S) * flicker_term_variance(floor)
                     + white ** 2 / SECONDS + lsb ** 2 / 12 / n)


@pytest.fixture(scope="module")
def runs():
    return host_samples({**TAPS, "words": "adis16488"}), host_samples({**TAPS, "gyro_range_dps": 75})


def test_the_wide_words_show_the_earth_rate_and_gravity_within_the_grade(runs):
    (gyro, accel, sc), _ = runs
    e = sc.imu.errors
    w_true, f_true = truth(sc)
    assert np.linalg.norm(w_true) == pytest.approx(EARTH_RATE)
    sg = predicted_sigma(deg_h(e.gyro_bias_deg_h), deg_h(e.gyro_bias_instability_deg_h),
                         math.radians(e.gyro_arw_deg_rt_h) / 60, math.radians(adis16488.GYRO_LSB_DPS), len(gyro))
    sa = predicted_sigma(ug(e.accel_bias_ug), ug(e.accel_bias_instability_ug), e.accel_vrw_m_s_rt_h / 60,
                         ug(adis16488.ACCEL_LSB_G * 1e6), len(accel))
    assert math.degrees(sg) * 3600 < 0.2  # the 0.04 deg/h class: 0.14 deg/h over 60 s
    assert np.abs(gyro.mean(axis=0) - w_true).max() < 4 * sg
    assert np.abs(accel.mean(axis=0) - f_true).max() < 4 * sa
    # the words move with the white noise (they are not stuck on one value)
    assert (gyro.std(axis=0) > 100 * math.radians(adis16488.GYRO_LSB_DPS)).all()


def test_the_same_run_through_the_14_bit_words_hides_it(runs):
    (_, _, sc), (gyro, accel, narrow) = runs
    w_true, _ = truth(narrow)
    assert (gyro == 0.0).all()  # 12.8 deg/h north and 8.0 deg/h up are below half an LSB
    assert np.abs(w_true).max() > 50 * deg_h(0.04)  # what those zeros miss
    assert (accel[:, :2] == accel[0, :2]).all()  # the level axes stick on one word
