"""The vehicle's magnetometer (HMC5883L-class, read by the DSP board): true attitude and the
earth's field -> body-frame field words (docs/emulator-models.md, "Magnetometer").

Frames as emulator.imu: navigation n (x, y of the area, +x at azimuth ``x_azimuth_deg``
clockwise from north, z up), body b (x forward, y left, z up). The earth's field at the
site (common.geomagnetic: IGRF-13, north/east/down) in n::

    B_n = N north_n + E east_n - D z_n,   north_n = (cos a, sin a, 0),
    east_n = (sin a, -cos a, 0),          a = the azimuth of north counter-clockwise from +x

and each reading, with the vehicle's soft iron S (3x3) and hard iron h (uT, body axes)::

    m = S C_bn B_n + h + n,   n ~ N(0, noise^2 I) per axis

quantised to the HMC5883L's 1090 LSB/gauss (0.09174 uT) and its 12-bit range; an axis
beyond -2048..2047 reads -4096 (the chip's overflow value). The noise comes from the
magnetometer's own random stream, so turning it on changes no other device's draws.
"""
from __future__ import annotations

import math

import numpy as np

from navtwin.common import geomagnetic
from navtwin.protocols import sins

from .imu import body_from_nav


def earth_field_nav(site, area, spec) -> np.ndarray:
    """The earth's field (uT) in the navigation frame at the scenario's site."""
    north, east, down = geomagnetic.field_ned(site.latitude_deg, site.longitude_deg, site.height_m,
                                              year=spec.year)
    a = math.radians(area.x_azimuth_deg)  # north, counter-clockwise from +x
    north_n = np.array([math.cos(a), math.sin(a), 0.0])
    east_n = np.array([math.sin(a), -math.cos(a), 0.0])
    return north * north_n + east * east_n + np.array([0.0, 0.0, -down])


class Magnetometer:
    """``read(t_ns)``: (M, 3) signed field words (x, y, z) at the given true times."""

    def __init__(self, spec, site, area, trajectory, rng: np.random.Generator) -> None:
        self.trajectory = trajectory
        self.rng = rng
        self.noise = spec.noise_ut
        self.soft = np.array(spec.soft_iron)
        self.hard = np.array(spec.hard_iron_ut)
        self.field_n = earth_field_nav(site, area, spec)

    def true_field(self, t_ns: np.ndarray) -> np.ndarray:
        """(M, 3) error-free field in body axes, uT."""
        k = self.trajectory.kinematics(t_ns)
        return body_from_nav(k.roll, k.pitch, k.yaw) @ self.field_n

    def read(self, t_ns: np.ndarray) -> np.ndarray:
        m = self.true_field(t_ns) @ self.soft.T + self.hard
        m = m + self.noise * self.rng.standard_normal(m.shape)
        words = np.rint(m / sins.MAG_LSB_UT).astype(np.int64)
        lo, hi = sins.MAG_WORD_RANGE
        return np.where((words < lo) | (words > hi), sins.MAG_OVERFLOW, words)
