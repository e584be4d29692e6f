"""Strapdown mechanization and alignment against synthetic IMU data with known truth.

The synthetic readings (tests/host/navsynth.py) are written independently with scipy's
Rotation: specific force f = a + (2 w_ie + w_en) x v - g and body rate = turn + earth +
transport rate, at the office latitude and local gravity.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navtwin.host.sins import (Alignment, Strapdown, euler_from_quat, quat_from_euler, quat_from_rotvec,
                       quat_multiply, quat_to_dcm)

from ..helpers import GRAVITY, LATITUDE_DEG
from .navsynth import ellipse, noisy_imu, perfect_imu

DT = 0.01


def run(tr, gyro, accel, **kw):
    """Strapdown started on the true state of tr[0]; returns (positions, yaws)."""
    sins = Strapdown(position=tr.p[0], velocity=(*tr.v[0], 0.0), latitude_deg=LATITUDE_DEG, local_gravity=GRAVITY,
                     **{"q": quat_from_euler(0.0, 0.0, tr.yaw[0]), **kw})
    sins.step(0.0, gyro[0], accel[0])
    p, yaw = [sins.p[:2].copy()], [sins.yaw]
    for k in range(1, len(tr.t)):
        sins.step(DT, gyro[k], accel[k])
        p.append(sins.p[:2].copy())
        yaw.append(sins.yaw)
    return np.array(p), np.array(yaw)


def test_quaternion_helpers_agree_with_scipy():
    rng = np.random.default_rng(3)
    for roll, pitch, yaw in rng.uniform(-1.4, 1.4, (20, 3)):
        q = quat_from_euler(roll, pitch, yaw)
        expected = Rotation.from_euler("ZYX", [yaw, pitch, roll])
        np.testing.assert_allclose(quat_to_dcm(q), expected.as_matrix(), atol=1e-14)
        np.testing.assert_allclose(euler_from_quat(q), (roll, pitch, yaw), atol=1e-12)
    for v in [*rng.normal(0, 1, (10, 3)), np.array([1e-7, -2e-7, 3e-8]), np.zeros(3)]:
        w, x, y, z = quat_from_rotvec(v)
        np.testing.assert_allclose([x, y, z, w], Rotation.from_rotvec(v).as_quat(canonical=False), atol=1e-15)
    a, b = Rotation.random(2, random_state=5)
    qa, qb = (np.roll(r.as_quat(), 1) for r in (a, b))
    np.testing.assert_allclose(quat_to_dcm(quat_multiply(qa, qb)), (a * b).as_matrix(), atol=1e-14)


@pytest.mark.parametrize("azimuth", [90.0, 30.0])
def test_stationary_unit_stays_put_with_earth_rate_and_gravity(azimuth):
    """10 minutes at rest, tilted mount, heading 0.7 rad: only rounding moves it."""
    t = np.arange(0.0, 600.0, DT)
    tr = ellipse(t, t_start=1e9)  # never starts
    tr.yaw[:] = 0.7
    gyro, accel = perfect_imu(tr, roll=0.02, pitch=-0.03, x_azimuth_deg=azimuth)
    sins = Strapdown(position=tr.p[0], q=quat_from_euler(0.02, -0.03, 0.7), latitude_deg=LATITUDE_DEG,
                     local_gravity=GRAVITY, x_azimuth_deg=azimuth)
    for k in range(len(t)):
        sins.step(DT if k else 0.0, gyro[k], accel[k])
    assert np.abs(sins.p[:2] - tr.p[0]).max() < 1e-6
    assert np.abs(sins.v).max() < 1e-8
    np.testing.assert_allclose(sins.euler, (0.02, -0.03, 0.7), atol=1e-9)


def test_earth_rate_compensation_is_what_keeps_it_still():
    """The same data mechanized at the wrong latitude sign: the uncompensated earth rate
    tilts the platform and the position runs away. The test can tell them apart."""
    t = np.arange(0.0, 60.0, DT)
    tr = ellipse(t, t_start=1e9)
    gyro, accel = perfect_imu(tr)
    p_ok, _ = run(tr, gyro, accel)
    sins = Strapdown(position=tr.p[0], q=quat_from_euler(0, 0, 0), latitude_deg=-LATITUDE_DEG, local_gravity=GRAVITY)
    for k in range(len(t)):
        sins.step(DT if k else 0.0, gyro[k], accel[k])
    assert np.abs(p_ok[-1] - tr.p[0]).max() < 1e-6
    assert np.hypot(*(sins.p[:2] - tr.p[0])) > 0.01


@pytest.mark.parametrize("semi,omega", [((2.0, 2.0), 0.5), ((4.0, 1.7), 0.12)])
def test_circle_and_ellipse_are_tracked(semi, omega):
    """Known rate and speed for two minutes: the track stays within millimetres."""
    t = np.arange(0.0, 120.0, DT)
    tr = ellipse(t, semi=semi, omega=omega)
    gyro, accel = perfect_imu(tr)
    p, yaw = run(tr, gyro, accel)
    assert np.hypot(*(p - tr.p).T).max() < 5e-3
    dyaw = np.angle(np.exp(1j * (yaw - tr.yaw)))
    assert np.abs(dyaw).max() < 1e-5
    # the vehicle really went round: the heading turned through several cycles
    assert np.abs(np.unwrap(tr.yaw)[-1] - tr.yaw[0]) > 2 * math.pi


def test_alignment_recovers_roll_pitch_and_gyro_bias():
    t = np.arange(0.0, 5.0, DT)
    tr = ellipse(t, t_start=1e9)
    tr.yaw[:] = -1.1
    gyro, accel = perfect_imu(tr, roll=0.04, pitch=-0.025)
    bias = np.array([0.004, -0.002, 0.003])
    al = Alignment()
    for g, f in zip(gyro + bias, accel):
        al.add(g, f)
    res = al.result(heading_rad=-1.1, latitude_rad=math.radians(LATITUDE_DEG))
    assert res.samples == len(t)
    assert res.roll == pytest.approx(0.04, abs=1e-12)
    assert res.pitch == pytest.approx(-0.025, abs=1e-12)
    np.testing.assert_allclose(res.gyro_bias, bias, atol=1e-12)
    assert res.specific_force == pytest.approx(GRAVITY, abs=1e-9)
    np.testing.assert_allclose(quat_to_dcm(res.q), quat_to_dcm(quat_from_euler(0.04, -0.025, -1.1)),
                               atol=1e-12)


def test_noisy_alignment_errors_are_within_the_noise_model():
    """ADIS16350 noise: the errors stay inside 4 sigma of what averaging N samples allows."""
    t = np.arange(0.0, 5.0, DT)
    tr = ellipse(t, t_start=1e9)
    gyro, accel = perfect_imu(tr, roll=0.01, pitch=0.02)
    rng = np.random.default_rng(11)
    bias = np.array([0.002, 0.001, -0.0015])
    gyro, accel = noisy_imu(gyro, accel, rng, gyro_bias=bias)
    al = Alignment()
    for g, f in zip(gyro, accel):
        al.add(g, f)
    res = al.result(0.0, math.radians(LATITUDE_DEG))
    n = len(t)
    sigma_bias = math.radians(4.2) / 60 / math.sqrt(DT) / math.sqrt(n)
    sigma_tilt = 2.0 / 60 / math.sqrt(DT) / math.sqrt(n) / GRAVITY
    assert np.abs(res.gyro_bias - bias).max() < 4 * sigma_bias
    assert abs(res.roll - 0.01) < 4 * sigma_tilt and abs(res.pitch - 0.02) < 4 * sigma_tilt


def test_aligned_bias_makes_a_biased_gyro_hold_heading():
    """A constant gyro bias removed by the alignment: the SINS holds heading and position."""
    t = np.arange(0.0, 65.0, DT)
    tr = ellipse(t, t_start=1e9)
    gyro, accel = perfect_imu(tr)
    gyro = gyro + np.array([0.003, -0.002, 0.01])
    al = Alignment()
    for g, f in zip(gyro[:500], accel[:500]):
        al.add(g, f)
    res = al.result(0.0, math.radians(LATITUDE_DEG))
    sins = Strapdown(position=tr.p[0], q=res.q, gyro_bias=res.gyro_bias, latitude_deg=LATITUDE_DEG,
                     local_gravity=GRAVITY)
    for k in range(499, len(t)):
        sins.step(DT if k > 499 else 0.0, gyro[k], accel[k])
    assert abs(sins.yaw) < 1e-9
    assert np.abs(sins.p[:2] - tr.p[0]).max() < 1e-6


def test_correct_removes_the_estimated_errors_and_keeps_plain_floats():
    """001's closed-loop feedback: p - dp, v - dv, and C = exp(-da x) C_computed (scipy's
    rotation, independent), from the numpy arrays an error-state filter gives. The state
    stays Python floats: numpy scalars in it made every later step about 4x slower."""
    q = quat_from_euler(0.01, -0.02, 0.9)
    sins = Strapdown(position=(6.0, 1.8), velocity=(0.3, -0.1, 0.0), q=q, latitude_deg=LATITUDE_DEG,
                     local_gravity=GRAVITY)
    dp, dv, da = np.array([0.2, -0.1]), np.array([0.05, 0.02]), np.array([1e-3, -2e-3, 0.03])
    sins.correct(dp, dv, da)
    np.testing.assert_allclose(sins.p, (5.8, 1.9, 0.0), atol=1e-15)
    np.testing.assert_allclose(sins.v, (0.25, -0.12, 0.0), atol=1e-15)
    want = Rotation.from_rotvec(-da) * Rotation.from_quat(np.roll(q, -1))
    np.testing.assert_allclose(quat_to_dcm(sins.q), want.as_matrix(), atol=1e-14)
    state = (*sins._p, *sins._v, *sins._q)
    assert {type(c) for c in state} == {float}
