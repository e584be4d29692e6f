"""The strapdown of host.sins for N seeds along a leading axis (000 eqs. 1-5, batched).

The mechanization is host.sins.Strapdown's, operation for operation: each component is an
(n,) array where the per-seed code has a Python float, and every expression keeps the
per-seed code's order of operations, so each seed's position, velocity and attitude equal
the per-seed strapdown's (to the last bit where numpy's sin, cos and atan2 round as libm's;
within 1e-15 where they do not). A step takes the rows *idx* of the seeds it moves, with
their own dt and samples.
"""
from __future__ import annotations

import copy
import math

import numpy as np

from navtwin.common.geodesy import meridian_radius, transverse_radius
# the per-seed products are written for any numbers: on tuples of (n,) arrays they are these
from navtwin.host.sins import area_from_enu, earth_rate_nav, mat_vec
from navtwin.host.sins import quat_multiply as qmul
from navtwin.host.sins import quat_to_dcm as dcm

from .seeds import ALL, whole


def from_rotvec(x, y, z):
    """host.sins.quat_from_rotvec, per seed (its series below 1e-4 rad)."""
    angle = np.sqrt(x * x + y * y + z * z)
    half = 0.5 * angle
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(angle < 1e-4, 0.5 - angle * angle / 48.0, np.sin(half) / angle)
    return (np.cos(half), k * x, k * y, k * z)


def put(a: np.ndarray, idx, columns) -> None:
    """The rows *idx* (host.batch.seeds.whole) of *a* (N, k) set to k columns (n,): in place,
    column by column, for every row; else stacked and scattered."""
    if idx is ALL:
        for k, c in enumerate(columns):
            a[:, k] = c
    else:
        a[idx] = np.stack(columns, 1)


class BatchStrapdown:
    """p (N, 3), v (N, 3), q (N, 4) and the gyro bias (N, 3) of N strapdowns on one site;
    a seed's row is set by :meth:`begin` (the alignment's result), or :meth:`take` from
    another's, before it steps. A track's own strapdown (an error-state track's) is also
    corrected (:meth:`correct`) and placed (:meth:`place`)."""

    def __init__(self, n: int, *, latitude_deg: float, altitude_m: float = 0.0,
                 x_azimuth_deg: float = 90.0) -> None:
        self.p = np.zeros((n, 3))
        self.v = np.zeros((n, 3))
        self.q = np.zeros((n, 4))
        self.gyro_bias = np.zeros((n, 3))
        self.prev = np.zeros((n, 6))  # the last sample, bias removed (gyro, accel)
        self.has_prev = np.zeros(n, bool)
        self.f_n = np.full((n, 3), np.nan)  # the last step's specific force, nav frame (Strapdown.f_n)
        lat = math.radians(latitude_deg)
        self._w_ie = tuple(earth_rate_nav(lat, x_azimuth_deg).tolist())
        self._area_from_enu = area_from_enu(x_azimuth_deg).tolist()
        self._enu_from_area = area_from_enu(x_azimuth_deg).T.tolist()
        self._r_m = float(meridian_radius(lat)) + altitude_m
        self._r_n = float(transverse_radius(lat)) + altitude_m
        self._tan_lat = math.tan(lat)

    def part(self, start: int, n: int) -> BatchStrapdown:
        """Rows start to start + n as the strapdowns of n seeds of their own: views, so a step
        of this stack's rows steps them (several strapdowns stepped in one call)."""
        part = copy.copy(self)
        for name in ("p", "v", "q", "gyro_bias", "prev", "has_prev", "f_n"):
            setattr(part, name, getattr(self, name)[start:start + n])
        return part

    def begin(self, idx: np.ndarray, position: np.ndarray, q: np.ndarray, gyro_bias: np.ndarray) -> None:
        """Seeds *idx* start at *position* (n, 2) at rest with attitude *q* (n, 4) and *gyro_bias*."""
        self.p[idx] = np.column_stack((position, np.zeros(len(idx))))
        self.v[idx] = 0.0
        self.q[idx] = q
        self.gyro_bias[idx] = gyro_bias
        self.has_prev[idx] = False

    def step(self, idx: np.ndarray, dt: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> np.ndarray:
        """host.sins.Strapdown.step for the seeds *idx*: dt (n,), gyro and accel (n, 3);
        returns their horizontal dv/dt (n, 2)."""
        idx = whole(idx, len(self.p))
        bx, by, bz = self.gyro_bias[idx].T
        gx, gy, gz = gyro.T
        gx, gy, gz = gx - bx, gy - by, gz - bz
        fx, fy, fz = accel.T
        prev, had = self.prev[idx], self.has_prev[idx]
        # held(): the trapezoid's mean with the previous sample, the sample itself without one
        w_ib = tuple(np.where(had, 0.5 * (now + before), now)
                     for now, before in zip((gx, gy, gz), prev[:, :3].T))
        f_b = tuple(np.where(had, 0.5 * (now + before), now)
                    for now, before in zip((fx, fy, fz), prev[:, 3:].T))
        put(self.prev, idx, (gx, gy, gz, fx, fy, fz))
        self.has_prev[idx] = True
        vx, vy, vz = self.v[idx].T
        ie_x, ie_y, ie_z = self._w_ie
        ve, vn, _ = mat_vec(self._enu_from_area, (vx, vy, vz))
        en_x, en_y, en_z = mat_vec(self._area_from_enu, (-vn / self._r_m, ve / self._r_n,
                                                         ve * self._tan_lat / self._r_n))
        # rotate(): half steps of the nav frame and the body, taken twice
        h = 0.5 * dt
        nav_half = from_rotvec((ie_x + en_x) * -h, (ie_y + en_y) * -h, (ie_z + en_z) * -h)
        body_half = from_rotvec(w_ib[0] * h, w_ib[1] * h, w_ib[2] * h)
        q = tuple(self.q[idx].T)
        q_mid = qmul(nav_half, qmul(q, body_half))
        qw, qx, qy, qz = qmul(nav_half, qmul(q_mid, body_half))
        norm = np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        put(self.q, idx, (qw / norm, qx / norm, qy / norm, qz / norm))
        wx, wy, wz = 2.0 * ie_x + en_x, 2.0 * ie_y + en_y, 2.0 * ie_z + en_z
        fn_x, fn_y, fn_z = f_n = mat_vec(dcm(q_mid), f_b)
        put(self.f_n, idx, f_n)
        ax = fn_x - (wy * vz - wz * vy)
        ay = fn_y - (wz * vx - wx * vz)
        s = 0.5 * dt * dt
        x, y, z = self.p[idx].T
        # p before v: p's step reads the old v (views of it when idx is every row)
        put(self.p, idx, (x + (vx * dt + ax * s), y + (vy * dt + ay * s), z + vz * dt))
        put(self.v, idx, (vx + ax * dt, vy + ay * dt, vz))
        return np.stack((ax, ay), 1)

    def take(self, idx: np.ndarray, other: BatchStrapdown) -> None:
        """Seeds *idx* in the state of *other*'s rows (host.sins.Strapdown.copy: a track's
        own strapdown, taken from the estimator's on the same site)."""
        for name in ("p", "v", "q", "gyro_bias", "prev", "has_prev", "f_n"):
            getattr(self, name)[idx] = getattr(other, name)[idx]

    def correct(self, idx: np.ndarray, dp: np.ndarray, dv: np.ndarray, da: np.ndarray) -> None:
        """host.sins.Strapdown.correct for the seeds *idx*: remove the estimated errors dp,
        dv (n, 2) of the horizontal position and velocity and da (n, 3) of the attitude
        (C_computed = exp(da x) C_true)."""
        idx = whole(idx, len(self.p))
        self.p[idx, :2] = self.p[idx, :2] - dp
        self.v[idx, :2] = self.v[idx, :2] - dv
        dax, day, daz = da.T
        qw, qx, qy, qz = qmul(from_rotvec(-dax, -day, -daz), tuple(self.q[idx].T))
        norm = np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        put(self.q, idx, (qw / norm, qx / norm, qy / norm, qz / norm))

    def place(self, idx: np.ndarray, p: np.ndarray, v: np.ndarray) -> None:
        """host.sins.Strapdown.place for the seeds *idx*: horizontal position and velocity
        (n, 2) set (a re-initialisation), the attitude kept."""
        self.p[idx, :2] = p
        self.v[idx, :2] = v

    def yaw(self, idx: np.ndarray) -> np.ndarray:
        """host.sins.euler_from_quat's yaw of the seeds *idx*."""
        w, x, y, z = self.q[idx].T
        return np.arctan2(2 * (x * y + w * z), 1 - 2 * (y * y + z * z))
