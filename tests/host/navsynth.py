"""Test-side synthetic lab data for the navigation math (no emulator involved).

An analytic trajectory on an ellipse (a circle when both semi-axes are equal) with a smooth
start, the perfect IMU readings it implies (specific force and body rates including local
gravity, the earth rate and Coriolis, written independently of host.sins with scipy's
Rotation), and TDMA range exchanges. Noise comes from a seeded numpy Generator.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..helpers import GRAVITY, LATITUDE_DEG

OMEGA_E = 7.2916e-5


@dataclass
class Trajectory:
    t: np.ndarray
    p: np.ndarray  # (N, 2)
    v: np.ndarray
    a: np.ndarray
    yaw: np.ndarray
    yaw_rate: np.ndarray


def ellipse(t, *, centre=(6.0, 3.5), semi=(4.0, 1.7), omega=0.12, t_start=0.0, ramp=0.0):
    """Counter-clockwise ellipse from its lowest point (heading 0 = +x there).

    The angle rate rises from 0 to ``omega`` between t_start and t_start + ramp (smoothstep,
    so the acceleration is continuous); before t_start the vehicle is at rest."""
    t = np.asarray(t, float)
    A, B = semi
    if ramp > 0:
        u = np.clip((t - t_start) / ramp, 0.0, 1.0)
        rate = omega * (3 * u**2 - 2 * u**3)
        accel = np.where((u > 0) & (u < 1), omega * (6 * u - 6 * u**2) / ramp, 0.0)
        theta = np.where(u < 1, omega * ramp * (u**3 - u**4 / 2),
                         omega * ramp / 2 + omega * (t - t_start - ramp))
    else:
        on = t >= t_start
        rate = np.where(on, omega, 0.0)
        accel = np.zeros_like(t)
        theta = np.where(on, omega * (t - t_start), 0.0)
    s, c = np.sin(theta), np.cos(theta)
    p = np.column_stack([centre[0] + A * s, centre[1] - B * c])
    tangent = np.column_stack([A * c, B * s])
    v = rate[:, None] * tangent
    a = accel[:, None] * tangent + (rate**2)[:, None] * np.column_stack([-A * s, B * c])
    yaw = np.arctan2(B * s, A * c)
    yaw_rate = rate * A * B / (A**2 * c**2 + B**2 * s**2)
    return Trajectory(t, p, v, a, yaw, yaw_rate)


def _radii(lat):
    e2, a = 6.69437999014e-3, 6378137.0
    w = 1 - e2 * math.sin(lat) ** 2
    return a * (1 - e2) / w**1.5, a / math.sqrt(w)


def perfect_imu(tr: Trajectory, *, latitude_deg=LATITUDE_DEG, gravity=GRAVITY, roll=0.0, pitch=0.0,
                x_azimuth_deg=90.0):
    """(gyro rad/s, specific force m/s^2), body x fwd / y left / z up, for a vehicle
    following ``tr`` with a constant roll and pitch of its body on the chassis. The area's
    +x points at ``x_azimuth_deg`` clockwise from north."""
    lat = math.radians(latitude_deg)
    r_m, r_n = _radii(lat)
    n = len(tr.t)
    v3 = np.column_stack([tr.v, np.zeros(n)])
    a3 = np.column_stack([tr.a, np.zeros(n)])
    # unit vectors of the area axes in (east, north): x at the azimuth, y 90 deg counter-clockwise
    az = math.radians(x_azimuth_deg)
    ex, ey = np.array([math.sin(az), math.cos(az)]), np.array([-math.cos(az), math.sin(az)])
    w_ie_en = OMEGA_E * math.cos(lat) * np.array([0.0, 1.0])  # horizontal part, along north
    w_ie = np.array([w_ie_en @ ex, w_ie_en @ ey, OMEGA_E * math.sin(lat)])
    v_en = np.outer(tr.v[:, 0], ex) + np.outer(tr.v[:, 1], ey)  # (east, north) velocity
    w_en_en = np.column_stack([-v_en[:, 1] / r_m, v_en[:, 0] / r_n])
    w_en = np.column_stack([w_en_en @ ex, w_en_en @ ey, v_en[:, 0] * math.tan(lat) / r_n])
    f_n = a3 + np.cross(2 * w_ie + w_en, v3) - np.array([0.0, 0.0, -gravity])
    rot = Rotation.from_euler("ZYX", np.column_stack([tr.yaw, np.full(n, pitch), np.full(n, roll)]))
    f_b = rot.inv().apply(f_n)
    # body rate = nav-frame turn (about nav z, the chassis is level) + earth + transport
    w_b = rot.inv().apply(np.column_stack([np.zeros(n), np.zeros(n), tr.yaw_rate]) + w_ie + w_en)
    return w_b, f_b


def noisy_imu(gyro, accel, rng: np.random.Generator, *, dt=0.01, arw_deg_rt_hr=4.2,
              vrw_m_s_rt_hr=2.0, gyro_bias=(0, 0, 0), accel_bias=(0, 0, 0)):
    """White noise from the ADIS16350 random walks plus constant biases."""
    g_sigma = math.radians(arw_deg_rt_hr) / 60.0 / math.sqrt(dt)
    a_sigma = vrw_m_s_rt_hr / 60.0 / math.sqrt(dt)
    return (gyro + np.asarray(gyro_bias) + rng.normal(0, g_sigma, gyro.shape),
            accel + np.asarray(accel_bias) + rng.normal(0, a_sigma, accel.shape))


def drive_after_rest(rng: np.random.Generator, *, align_s: float, duration_s: float, **noise):
    """A run for a fusion track: at rest for *align_s* with a perfect IMU (so the alignment
    is exact), then an ellipse in the office with the IMU of :func:`noisy_imu` (*noise*: its
    keywords). Returns (trajectory function, times, truth, gyro, accel) at 100 Hz."""
    def traj(t):
        return ellipse(t, omega=0.1, t_start=align_s + 1.0, ramp=4.0)

    t = np.arange(0.0, duration_s, 0.01)
    tr = traj(t)
    gyro, accel = perfect_imu(tr)
    moving = t >= align_s
    ng, na = noisy_imu(gyro, accel, rng, **noise)
    gyro[moving], accel[moving] = ng[moving], na[moving]
    return traj, t, tr, gyro, accel


@dataclass
class GeodeticRun:
    t: np.ndarray
    lat: np.ndarray  # rad
    lon: np.ndarray  # rad (constant: along the meridian)
    v_north: np.ndarray  # m/s
    gyro: np.ndarray  # (N, 3) rad/s, body x forward (north), y left (west), z up
    accel: np.ndarray  # (N, 3) m/s^2


def geodetic_north(*, lat0_deg=32.0, lon0_deg=118.0, park_s=60.0, duration_s=300.0, speed=1.0,
                   ramp_s=2.0, gravity=9.7948, dt=0.01) -> GeodeticRun:
    """A level vehicle at height 0 parked at ``lat0_deg`` for ``park_s``, then driving due north
    along its meridian, its speed rising to ``speed`` over ``ramp_s`` (smoothstep), at a
    constant speed after, with the perfect IMU it implies on the curved earth (written from
    the physics, not from host.geodetic): with v = (0, v_N, 0) ENU, w_en = (-v_N / R_M, 0, 0),
    the body (x north, y west, z up) turns at w_ie(L) + w_en, so the gyros read
    (W cos L, v_N / R_M, W sin L); the specific force f^n = dv/dt + (2 w_ie + w_en) x v - g^n
    = (-2 W sin L v_N, a_N, g - v_N^2 / R_M) reads (a_N, 2 W sin L v_N, g - v_N^2 / R_M).
    The latitude is L' = v_N / R_M(L), integrated to 1e-13 rad (scipy's solve_ivp)."""
    from scipy.integrate import solve_ivp

    t = np.arange(0.0, duration_s, dt)
    u = np.clip((t - park_s) / ramp_s, 0.0, 1.0)
    v = speed * (3 * u**2 - 2 * u**3)
    a = np.where((u > 0) & (u < 1), speed * (6 * u - 6 * u**2) / ramp_s, 0.0)

    def speed_at(tt):
        uu = min(max((tt - park_s) / ramp_s, 0.0), 1.0)
        return speed * (3 * uu**2 - 2 * uu**3)

    sol = solve_ivp(lambda tt, y: [speed_at(tt) / _radii(y[0])[0]], (0.0, duration_s),
                    [math.radians(lat0_deg)], t_eval=t, rtol=1e-13, atol=1e-15, max_step=1.0)
    lat = sol.y[0]
    r_m = np.array([_radii(x)[0] for x in lat])
    sl, cl = np.sin(lat), np.cos(lat)
    gyro = np.column_stack([OMEGA_E * cl, v / r_m, OMEGA_E * sl])
    accel = np.column_stack([a, 2 * OMEGA_E * sl * v, gravity - v**2 / r_m])
    return GeodeticRun(t, lat, np.full_like(t, math.radians(lon0_deg)), v, gyro, accel)


def exchanges(traj_fn, anchors, *, duration, sigma, rng: np.random.Generator, cycle=0.1, slot=0.025,
              tag_height=0.0, t0=0.0):
    """TDMA range exchanges: list of (t, anchor, distance); anchor k's slot at cycle start +
    k * slot; the distance is the 3-D range at that moment plus N(0, sigma^2)."""
    ids = sorted(anchors)
    out = []
    k = 0
    while t0 + k * cycle < duration:
        ts = np.array([t0 + k * cycle + j * slot for j in range(len(ids))])
        tr = traj_fn(ts)
        for j, a in enumerate(ids):
            ax, ay, az = anchors[a]
            d = math.sqrt((tr.p[j, 0] - ax) ** 2 + (tr.p[j, 1] - ay) ** 2 + (tag_height - az) ** 2)
            out.append((float(ts[j]), a, d + rng.normal(0.0, sigma)))
        k += 1
    return out


def record(kind: str, args: tuple):
    """The measurement record of a synthetic call ("imu" | "range" | "restart", its args)."""
    from navtwin.host.measurements import Exchange, ImuSample, Restart

    return {"imu": ImuSample, "range": Exchange, "restart": Restart}[kind](*args)
