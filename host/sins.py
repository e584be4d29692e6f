"""Strapdown inertial navigation: coarse alignment and mechanization (000 section 3.1).

Frames
    Navigation frame n: local level, x and y along the lab area's axes, z up. The area's +x
    points at azimuth ``x_azimuth_deg`` (clockwise from north); the default 90 makes n the
    east-north-up frame of 000. The earth and transport rates of eq. 3 (written in ENU)
    are rotated into the area axes.
    Body frame b: x forward, y left, z up, so a level unit at rest reads +g on z.
    Attitude: unit quaternion q (scalar first) with v^n = q v^b q*, i.e. C_b^n.
    Euler angles: C_b^n = Rz(yaw) Ry(pitch) Rx(roll), right-handed about each axis: yaw 0 =
    body x along area +x, counter-clockwise positive; positive pitch is a rotation about
    the body's left axis (nose down), positive roll about the forward axis (left side up).

Mechanization, per IMU sample over dt (000 eqs. 1-5)::

    w_ie^n = W_ie (0, cos L, sin L)                                        (eq. 3)
    w_en^n = (-v_N / (R_M + h), v_E / (R_N + h), v_E tan L / (R_N + h))   (eq. 3)
    w_in^n = w_ie^n + w_en^n                           (the nav frame's inertial rate)
    q     <- exp(w_in^n dt)* (x) q (x) exp((w_ib^b - b_g) dt)   (exact for constant rates)
    f^n    = C_b^n(mid-interval) f^b                   (000 eq. 2 decomposition)
    dv/dt  = f^n - (2 w_ie^n + w_en^n) x v^n + g^n,  g^n = (0, 0, -g)     (eqs. 2, 4)
    v_U    = 0                                         (eq. 5: the car stays on the floor)
    p     <- p + v dt + dv/dt dt^2 / 2

Each sample is taken as the instantaneous rate and specific force at its time stamp; the
interval to the previous sample uses their mean (trapezoid), second-order accurate.

R_M and R_N are the WGS-84 meridian and prime-vertical radii at the latitude L. Over a
room the latitude is treated as constant.

Alignment (coarse, on the stationary start): the mean specific force is -g^n seen in
body axes, so roll = atan2(f_y, f_z), pitch = atan2(-f_x, hypot(f_y, f_z)). A MEMS gyro
(ARW 2.5 deg/sqrt(h) as read, bias instability 0.015 deg/s = 54 deg/h) cannot sense the
earth's 15 deg/h, so it cannot gyrocompass: the heading is the configured initial
heading. The gyro bias is the mean rate minus the earth rate in body axes,
b_g = mean(w_ib^b) - C_n^b w_ie^n. An accelerometer bias cannot be told apart from a
tilt at rest; it is absorbed in roll and pitch (and cancels while the unit stays level).
"""
from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from navtwin.common.earth import EARTH_RATE
from navtwin.common.geodesy import meridian_radius, transverse_radius


def area_from_enu(x_azimuth_deg: float = 90.0) -> np.ndarray:
    """Rotation taking east-north-up components to area components (x at the azimuth)."""
    a = math.radians(x_azimuth_deg)
    return np.array([[math.sin(a), math.cos(a), 0.0], [-math.cos(a), math.sin(a), 0.0], [0.0, 0.0, 1.0]])


def earth_rate_nav(latitude_rad: float, x_azimuth_deg: float = 90.0) -> np.ndarray:
    """w_ie^n = W_ie (0, cos L, sin L) in ENU (000 eq. 3), in area axes."""
    enu = EARTH_RATE * np.array([0.0, math.cos(latitude_rad), math.sin(latitude_rad)])
    return area_from_enu(x_azimuth_deg) @ enu


Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # (w, x, y, z)

# The per-sample math works on tuples of Python floats: at 3 and 4 components a numpy call
# costs more than the arithmetic (docs/filters.md, "Speed").


def quat_multiply(p: Sequence[float], q: Sequence[float]) -> Quat:
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


def quat_from_rotvec(v: Sequence[float]) -> Quat:
    """exp of a rotation vector (rad): the quaternion of a rotation by |v| about v."""
    x, y, z = v
    angle = math.sqrt(x * x + y * y + z * z)
    half = 0.5 * angle
    # sin(half)/angle by its series for tiny angles, where the quotient loses precision
    k = 0.5 - angle * angle / 48.0 if angle < 1e-4 else math.sin(half) / angle
    return (math.cos(half), k * x, k * y, k * z)


def quat_to_dcm(q: Sequence[float]) -> tuple[Vec3, Vec3, Vec3]:
    """C_b^n of q (v^n = C v^b), as three rows."""
    w, x, y, z = q
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def mat_vec(m: Sequence[Sequence[float]], v: Sequence[float]) -> Vec3:
    """m v for a 3x3 m given by rows."""
    (a, b, c), (d, e, f), (g, h, i) = m
    x, y, z = v
    return (a * x + b * y + c * z, d * x + e * y + f * z, g * x + h * y + i * z)


def quat_from_euler(roll: float, pitch: float, yaw: float) -> Quat:
    """q of C_b^n = Rz(yaw) Ry(pitch) Rx(roll)."""
    qz = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    qy = (math.cos(pitch / 2), 0.0, math.sin(pitch / 2), 0.0)
    qx = (math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0)
    return quat_multiply(quat_multiply(qz, qy), qx)


def euler_from_quat(q: Sequence[float]) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of q, inverse of :func:`quat_from_euler`."""
    C = quat_to_dcm(q)
    return (math.atan2(C[2][1], C[2][2]),
            math.asin(max(-1.0, min(1.0, -C[2][0]))),
            math.atan2(C[1][0], C[0][0]))


def held(gyro: Vec3, accel: Vec3, prev) -> tuple[Vec3, Vec3]:
    """The rate and specific force held over an interval: the mean of its two samples
    (trapezoid), *prev* the interval's first ((gyro, accel), None for the first sample)."""
    if prev is None:
        return gyro, accel
    (gx0, gy0, gz0), (fx0, fy0, fz0) = prev
    gx, gy, gz = gyro
    fx, fy, fz = accel
    return ((0.5 * (gx + gx0), 0.5 * (gy + gy0), 0.5 * (gz + gz0)),
            (0.5 * (fx + fx0), 0.5 * (fy + fy0), 0.5 * (fz + fz0)))


def rotate(q: Quat, w_in: Vec3, w_ib: Vec3, dt: float) -> tuple[Quat, Quat]:
    """The attitude C_b^n after dt and at mid-interval. The body turns by w_ib against
    inertial space and the nav frame by w_in: q(t+dt) = exp(w_in dt)* (x) q (x) exp(w_ib dt),
    exact for constant rates; the half step (mid-interval attitude) taken twice is the whole
    step."""
    h = 0.5 * dt
    nav_half = quat_from_rotvec((w_in[0] * -h, w_in[1] * -h, w_in[2] * -h))
    body_half = quat_from_rotvec((w_ib[0] * h, w_ib[1] * h, w_ib[2] * h))
    q_mid = quat_multiply(nav_half, quat_multiply(q, body_half))
    qw, qx, qy, qz = quat_multiply(nav_half, quat_multiply(q_mid, body_half))
    norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    return (qw / norm, qx / norm, qy / norm, qz / norm), q_mid


@dataclass(frozen=True, slots=True)
class AlignmentResult:
    q: Quat  # initial attitude C_b^n
    gyro_bias: np.ndarray  # rad/s, body axes
    roll: float
    pitch: float
    yaw: float
    samples: int
    specific_force: float  # |mean f^b|, m/s^2: about g when the unit was at rest


class Alignment:
    """Accumulates the stationary start; :meth:`result` levels and estimates the gyro bias."""

    def __init__(self):
        self.samples = 0
        self._gyro = np.zeros(3)
        self._accel = np.zeros(3)

    @classmethod
    def of(cls, samples: int, gyro_sum, accel_sum) -> Alignment:
        """The alignment that added *samples* samples summing to these (host.batch's rows)."""
        a = cls()
        a.samples, a._gyro, a._accel = samples, np.array(gyro_sum, float), np.array(accel_sum, float)
        return a

    def add(self, gyro: np.ndarray, accel: np.ndarray) -> None:
        self.samples += 1
        self._gyro += gyro
        self._accel += accel

    def result(self, heading_rad: float, latitude_rad: float, x_azimuth_deg: float = 90.0) -> AlignmentResult:
        if self.samples == 0:
            raise ValueError("alignment needs at least one IMU sample")
        f = self._accel / self.samples
        roll = math.atan2(f[1], f[2])
        pitch = math.atan2(-f[0], math.hypot(f[1], f[2]))
        q = quat_from_euler(roll, pitch, heading_rad)
        C = np.array(quat_to_dcm(q))
        bias = self._gyro / self.samples - C.T @ earth_rate_nav(latitude_rad, x_azimuth_deg)
        return AlignmentResult(q, bias, roll, pitch, heading_rad, self.samples, float(np.linalg.norm(f)))


class Strapdown:
    """The pure SINS: attitude, velocity and position from IMU samples alone."""

    def __init__(self, *, position, q: Sequence[float], gyro_bias=(0.0, 0.0, 0.0),
                 velocity=(0.0, 0.0, 0.0), latitude_deg: float, local_gravity: float,
                 altitude_m: float = 0.0, x_azimuth_deg: float = 90.0):
        self._p: Vec3 = tuple(float(c) for c in [*position, 0.0][:3])
        self._v: Vec3 = tuple(float(c) for c in velocity)
        self._q: Quat = tuple(float(c) for c in q)
        self.gyro_bias: Vec3 = tuple(float(c) for c in gyro_bias)
        lat = math.radians(latitude_deg)
        self._w_ie: Vec3 = tuple(earth_rate_nav(lat, x_azimuth_deg).tolist())
        self._area_from_enu = area_from_enu(x_azimuth_deg).tolist()
        self._enu_from_area = area_from_enu(x_azimuth_deg).T.tolist()
        # once: over a room the latitude is constant
        r_m, r_n = float(meridian_radius(lat)), float(transverse_radius(lat))
        self._r_m, self._r_n = r_m + altitude_m, r_n + altitude_m
        self._tan_lat = math.tan(lat)
        self.local_gravity = float(local_gravity)  # g^n = (0, 0, -g) acts on v_U alone, which eq. 5 holds at 0
        self._prev: tuple[Vec3, Vec3] | None = None  # last sample, bias removed
        self.f_n: Vec3 = (0.0, 0.0, self.local_gravity)  # the last step's specific force, nav frame

    @property
    def p(self) -> np.ndarray:
        """Position (m), nav frame."""
        return np.array(self._p)

    @property
    def v(self) -> np.ndarray:
        """Velocity (m/s), nav frame."""
        return np.array(self._v)

    @property
    def q(self) -> np.ndarray:
        """Attitude C_b^n as a quaternion (w, x, y, z)."""
        return np.array(self._q)

    def transport_rate(self) -> Vec3:
        """w_en^n of 000 eq. 3 (ENU), in area axes."""
        ve, vn, _ = mat_vec(self._enu_from_area, self._v)
        return mat_vec(self._area_from_enu, (-vn / self._r_m, ve / self._r_n, ve * self._tan_lat / self._r_n))

    def step(self, dt: float, gyro: Sequence[float], accel: Sequence[float]) -> Vec3:
        """Integrate from the previous sample to this one, ``dt`` later.

        Samples are the instantaneous rates (rad/s) and specific force (m/s^2) at their time
        stamps; over the interval their mean (trapezoid) is held; with dt = 0 the sample is
        only recorded (the start of the first interval). Returns dv/dt in the nav frame (its
        horizontal part is the filters' acceleration measurement)."""
        bx, by, bz = self.gyro_bias
        gx, gy, gz = gyro
        gx, gy, gz = gx - bx, gy - by, gz - bz
        fx, fy, fz = accel
        w_ib, f_b = held((gx, gy, gz), (fx, fy, fz), self._prev)
        self._prev = ((gx, gy, gz), (fx, fy, fz))
        ie_x, ie_y, ie_z = self._w_ie
        en_x, en_y, en_z = self.transport_rate()
        self._q, q_mid = rotate(self._q, (ie_x + en_x, ie_y + en_y, ie_z + en_z), w_ib, dt)
        # dv/dt = C_b^n f^b - (2 w_ie + w_en) x v + g^n, horizontal: v_U = 0 on the floor (eq. 5)
        wx, wy, wz = 2.0 * ie_x + en_x, 2.0 * ie_y + en_y, 2.0 * ie_z + en_z
        vx, vy, vz = self._v
        self.f_n = fn_x, fn_y, _ = mat_vec(quat_to_dcm(q_mid), f_b)
        ax = fn_x - (wy * vz - wz * vy)
        ay = fn_y - (wz * vx - wx * vz)
        s = 0.5 * dt * dt
        x, y, z = self._p
        self._p = (x + (vx * dt + ax * s), y + (vy * dt + ay * s), z + vz * dt)
        self._v = (vx + ax * dt, vy + ay * dt, vz)
        return (ax, ay, 0.0)

    def copy(self) -> Strapdown:
        """An independent strapdown in the same state (a track that corrects its own)."""
        return copy.copy(self)  # its state is tuples and floats: nothing shared changes

    def correct(self, dp: Sequence[float], dv: Sequence[float], da: Sequence[float]) -> None:
        """Closed-loop feedback of an error-state filter (001 sect. 2): remove the estimated
        errors (computed minus true) of the horizontal position ``dp`` and velocity ``dv``
        and the attitude error ``da`` (rad, nav frame: C_computed = exp(da x) C_true)."""
        # plain floats: numpy scalars here would make every later step several times slower
        (dpx, dpy), (dvx, dvy), (dax, day, daz) = map(float, dp), map(float, dv), map(float, da)
        x, y, z = self._p
        vx, vy, vz = self._v
        self._p = (x - dpx, y - dpy, z)
        self._v = (vx - dvx, vy - dvy, vz)
        qw, qx, qy, qz = quat_multiply(quat_from_rotvec((-dax, -day, -daz)), self._q)
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        self._q = (qw / norm, qx / norm, qy / norm, qz / norm)

    def place(self, position: Sequence[float], velocity: Sequence[float]) -> None:
        """Put the strapdown at a horizontal position and velocity (a re-initialisation),
        its attitude kept."""
        self._p = (float(position[0]), float(position[1]), self._p[2])
        self._v = (float(velocity[0]), float(velocity[1]), self._v[2])

    @property
    def euler(self) -> tuple[float, float, float]:
        return euler_from_quat(self._q)

    @property
    def yaw(self) -> float:
        return self.euler[2]
