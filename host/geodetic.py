"""003's geodetic strapdown: latitude, longitude, height, velocity east-north-up and attitude
body -> ENU from IMU samples alone (003 sect. 3; the mechanisation 003 leaves to "the SINS",
written as PSINS / Titterton & Weston ch. 3 / Groves ch. 5.4 write it).

The flat strapdown of 000 (host.sins) holds the local level of the site and no transport
rate: right over a room. Over 003's 1.5 km the local level turns with the vehicle (the
transport rate w_en, 2.5e-4 rad over the run) and the earth rate with the latitude; this one
carries both. The host.sins flat strapdown is left as it is for 000's and 001's tracks.

Frames. Navigation n: east, north, up (ENU) at the vehicle's current position. Body b: x
forward, y left, z up (host.sins). Attitude: unit quaternion q (scalar first), v^n = q v^b q*,
i.e. C_b^n. Position: geodetic latitude L, longitude lambda (rad) and ellipsoid height h (m).

Mechanisation, per IMU sample over dt, with R_M, R_N the WGS-84 radii
(common.geodesy.meridian_radius, transverse_radius) at L::

    w_ie^n = W_ie (0, cos L, sin L)
    w_en^n = (-v_N / (R_M + h), v_E / (R_N + h), v_E tan L / (R_N + h))
    w_in^n = w_ie^n + w_en^n
    q     <- exp(w_in^n dt)* (x) q (x) exp((w_ib^b - b_g) dt)   (half steps, mid-interval q)
    f^n    = C_b^n(mid-interval) (f^b - b_a)
    dv/dt  = f^n - (2 w_ie^n + w_en^n) x v^n + (0, 0, -g)
    v     <- v + dv/dt dt
    L     <- L + v_N,mid dt / (R_M + h),  lambda <- lambda + v_E,mid dt / ((R_N + h) cos L),
    h     <- h + v_U,mid dt                (v_mid the interval's mean velocity)

with the rates and forces of the interval the mean of its two samples (trapezoid, as
host.sins), the earth and transport rates and the Coriolis term of the interval's start. g is
the host config's ``local_gravity``, constant: the lab's emulator holds it so (the normal
gravity's change over 1.5 km and a few metres of height, 1e-5 m/s^2, is left out). The
vertical channel is integrated free: nothing aids it (003 aids latitude and longitude);
with constant gravity it drifts as the double integral of its errors, without the
instability of a height-dependent gravity.

b_g, b_a: the gyro drift and accelerometer bias the error-state filter has estimated and fed
back (host.filters.geodetic); zero on a free strapdown.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Sequence

from navtwin.common.earth import EARTH_RATE
from navtwin.common.geodesy import meridian_radius, transverse_radius

from .sins import (Quat, Vec3, euler_from_quat, held, mat_vec, quat_from_rotvec, quat_multiply, quat_to_dcm,
                   rotate)


class GeodeticStrapdown:
    """The state (module docstring) and its integration; :meth:`correct` takes a filter's
    feedback."""

    def __init__(self, *, latitude_rad: float, longitude_rad: float, height_m: float = 0.0,
                 velocity=(0.0, 0.0, 0.0), q: Sequence[float], local_gravity: float,
                 gyro_bias=(0.0, 0.0, 0.0), accel_bias=(0.0, 0.0, 0.0)):
        self.lat, self.lon, self.h = float(latitude_rad), float(longitude_rad), float(height_m)
        self._v: Vec3 = tuple(float(c) for c in velocity)
        self._q: Quat = tuple(float(c) for c in q)
        self.gyro_bias: Vec3 = tuple(float(c) for c in gyro_bias)
        self.accel_bias: Vec3 = tuple(float(c) for c in accel_bias)
        self.local_gravity = float(local_gravity)
        self._prev: tuple[Vec3, Vec3] | None = None  # last sample, biases removed
        self.f_n: Vec3 = (0.0, 0.0, self.local_gravity)  # the last interval's specific force, ENU

    # -- the earth at the current point -------------------------------------------------------
    def radii(self) -> tuple[float, float]:
        """(R_M + h, R_N + h) at the current position (m)."""
        return meridian_radius(self.lat) + self.h, transverse_radius(self.lat) + self.h

    def earth_rate(self) -> Vec3:
        """w_ie^n (rad/s, ENU) at the current latitude."""
        return (0.0, EARTH_RATE * math.cos(self.lat), EARTH_RATE * math.sin(self.lat))

    def transport_rate(self) -> Vec3:
        """w_en^n (rad/s, ENU) at the current position and velocity."""
        rm, rn = self.radii()
        ve, vn, _ = self._v
        return (-vn / rm, ve / rn, ve * math.tan(self.lat) / rn)

    # -- state ----------------------------------------------------------------------------------
    @property
    def v(self) -> tuple[float, float, float]:
        """Velocity (m/s), ENU."""
        return self._v

    @property
    def q(self) -> Quat:
        """Attitude C_b^n (ENU) as a quaternion (w, x, y, z)."""
        return self._q

    def dcm(self) -> tuple[Vec3, Vec3, Vec3]:
        """C_b^n (body -> ENU) as three rows."""
        return quat_to_dcm(self._q)

    @property
    def euler(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) of C_b^n as host.sins defines them; yaw counter-clockwise from east."""
        return euler_from_quat(self._q)

    def step(self, dt: float, gyro: Sequence[float], accel: Sequence[float]) -> None:
        """Integrate from the previous sample to this one, ``dt`` later (host.sins.Strapdown.step:
        samples are the instantaneous rate (rad/s) and specific force (m/s^2) at their time
        stamps; with dt = 0 the sample is only recorded)."""
        bgx, bgy, bgz = self.gyro_bias
        bax, bay, baz = self.accel_bias
        gx, gy, gz = gyro
        fx, fy, fz = accel
        gx, gy, gz, fx, fy, fz = gx - bgx, gy - bgy, gz - bgz, fx - bax, fy - bay, fz - baz
        w_ib, f_b = held((gx, gy, gz), (fx, fy, fz), self._prev)
        self._prev = ((gx, gy, gz), (fx, fy, fz))
        ie_x, ie_y, ie_z = self.earth_rate()
        en_x, en_y, en_z = self.transport_rate()
        self._q, q_mid = rotate(self._q, (ie_x + en_x, ie_y + en_y, ie_z + en_z), w_ib, dt)
        # dv/dt = C_b^n f^b - (2 w_ie + w_en) x v + g^n
        wx, wy, wz = 2.0 * ie_x + en_x, 2.0 * ie_y + en_y, 2.0 * ie_z + en_z
        vx, vy, vz = self._v
        self.f_n = fn_x, fn_y, fn_z = mat_vec(quat_to_dcm(q_mid), f_b)
        ax = fn_x - (wy * vz - wz * vy)
        ay = fn_y - (wz * vx - wx * vz)
        az = fn_z - (wx * vy - wy * vx) - self.local_gravity
        v1 = (vx + ax * dt, vy + ay * dt, vz + az * dt)
        rm, rn = self.radii()
        ve, vn, vu = 0.5 * (vx + v1[0]), 0.5 * (vy + v1[1]), 0.5 * (vz + v1[2])
        self.lon += ve * dt / (rn * math.cos(self.lat))
        self.lat += vn * dt / rm
        self.h += vu * dt
        self._v = v1

    def copy(self) -> GeodeticStrapdown:
        """An independent strapdown in the same state."""
        return copy.copy(self)  # its state is tuples and floats

    def correct(self, dv: Sequence[float], phi: Sequence[float], dp: Sequence[float],
                d_accel_bias: Sequence[float] = (0.0, 0.0, 0.0),
                d_gyro_drift: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        """Closed-loop feedback (host.filters.geodetic's errors, computed minus true):
        velocity error ``dv`` (m/s, ENU), misalignment ``phi`` (rad, ENU; C_computed =
        (I - phi x) C_true), position error ``dp`` (dL, dlambda rad, dh m), and the
        accelerometer bias and gyro drift left in the samples (true minus removed)."""
        (dve, dvn, dvu), (px, py, pz) = map(float, dv), map(float, phi)
        dl, dlam, dh = map(float, dp)
        ve, vn, vu = self._v
        self._v = (ve - dve, vn - dvn, vu - dvu)
        qw, qx, qy, qz = quat_multiply(quat_from_rotvec((px, py, pz)), self._q)
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        self._q = (qw / norm, qx / norm, qy / norm, qz / norm)
        self.lat, self.lon, self.h = self.lat - dl, self.lon - dlam, self.h - dh
        self.accel_bias = tuple(b + float(d) for b, d in zip(self.accel_bias, d_accel_bias))
        self.gyro_bias = tuple(b + float(d) for b, d in zip(self.gyro_bias, d_gyro_drift))
        self._prev = None if self._prev is None else self._unbias(d_accel_bias, d_gyro_drift)

    def _unbias(self, d_accel_bias, d_gyro_drift) -> tuple[Vec3, Vec3]:
        """The last sample with the new biases removed too (the next interval's mean uses it)."""
        g, f = self._prev
        return (tuple(a - float(d) for a, d in zip(g, d_gyro_drift)),
                tuple(a - float(d) for a, d in zip(f, d_accel_bias)))

    def place(self, latitude_rad: float, longitude_rad: float, velocity=(0.0, 0.0, 0.0)) -> None:
        """Put the strapdown at a position and velocity (a re-initialisation), its attitude,
        height and biases kept."""
        self.lat, self.lon = float(latitude_rad), float(longitude_rad)
        self._v = tuple(float(c) for c in velocity)
