"""Geodetic positions and the lab's local frame, as both sides convert them (WGS-84).

The local frame is the scenario's navigation frame n placed on the earth: its origin
(local x, y, z = 0, 0, 0) is the site (``[site] latitude_deg, longitude_deg, height_m``),
z is the ellipsoid normal there (up), and x points at azimuth A = ``[area] x_azimuth_deg``
(clockwise from north) in the tangent plane, y 90 deg counter-clockwise from x. With the
east, north, up (ENU) coordinates e, n, u of a point about the origin::

    x = e sin A + n cos A,    y = -e cos A + n sin A,    z = u        (A = 90: x east, y north)

ENU is exact, through earth-centred earth-fixed (ECEF) coordinates: a geodetic latitude
phi, longitude lam and ellipsoid height h give, with N = a / sqrt(1 - e^2 sin^2 phi)::

    X = (N + h) cos phi cos lam,   Y = (N + h) cos phi sin lam,   Z = (N (1 - e^2) + h) sin phi

and the ECEF difference from the origin rotated into (e, n, u) at the origin's phi0, lam0::

    e = -sin lam0 dX + cos lam0 dY
    n = -sin phi0 cos lam0 dX - sin phi0 sin lam0 dY + cos phi0 dZ
    u =  cos phi0 cos lam0 dX + cos phi0 sin lam0 dY + sin phi0 dZ

Back from ECEF to geodetic: longitude atan2(Y, X), latitude by fixed-point iteration of
phi = atan2(Z + e^2 N sin phi, p), p = hypot(X, Y) (converges to 1e-12 rad in a few steps
off the poles), h = p / cos phi - N. The plane is tangent: a point on the ellipsoid s
metres from the origin has z ~ -s^2 / (2 R) (0.18 m at 1.5 km): the emulator's positions
stay in the plane, while its IMU senses the local level of each point (docs/emulator-models.md
2.1, what is still flat).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navtwin.common.earth import WGS84_A, WGS84_E2


def ecef(latitude_deg, longitude_deg, height_m=0.0) -> np.ndarray:
    """(..., 3) ECEF coordinates (m) of geodetic positions (deg, deg, m; arrays broadcast)."""
    lat, lon = np.radians(latitude_deg), np.radians(longitude_deg)
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = np.asarray(height_m, dtype=float)
    return np.stack(np.broadcast_arrays((n + h) * np.cos(lat) * np.cos(lon),
                                        (n + h) * np.cos(lat) * np.sin(lon),
                                        (n * (1.0 - WGS84_E2) + h) * np.sin(lat)), axis=-1)


def geodetic(xyz) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(latitude deg, longitude deg, height m) of ECEF points (..., 3)."""
    x, y, z = np.moveaxis(np.asarray(xyz, dtype=float), -1, 0)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(10):  # each step gains about 3 digits; 10 is far past convergence
        n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        lat, was = np.arctan2(z + WGS84_E2 * n * np.sin(lat), p), lat
        if np.array_equal(lat, was):  # a fixed point: every later step gives it again
            break
    n = WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    height = p / np.cos(lat) - n
    return np.degrees(lat), np.degrees(np.arctan2(y, x)), height


@dataclass(frozen=True)
class LocalFrame:
    """The lab's local frame at a geodetic origin, +x at azimuth *x_azimuth_deg*."""

    latitude_deg: float
    longitude_deg: float
    height_m: float = 0.0
    x_azimuth_deg: float = 90.0

    @classmethod
    def of(cls, site, area) -> "LocalFrame":
        """The frame of a scenario's ``[site]`` and ``[area]`` tables."""
        return cls(site.latitude_deg, site.longitude_deg, site.height_m, area.x_azimuth_deg)

    def _axes(self) -> np.ndarray:
        """Rows: the local x, y, z axes in ECEF."""
        lat, lon = math.radians(self.latitude_deg), math.radians(self.longitude_deg)
        east = np.array([-math.sin(lon), math.cos(lon), 0.0])
        north = np.array([-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)])
        up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
        a = math.radians(self.x_azimuth_deg)
        return np.stack((east * math.sin(a) + north * math.cos(a),
                         -east * math.cos(a) + north * math.sin(a), up))

    def local(self, latitude_deg, longitude_deg, height_m=0.0) -> np.ndarray:
        """(..., 3) local x, y, z (m) of geodetic positions."""
        origin = ecef(self.latitude_deg, self.longitude_deg, self.height_m)
        return (ecef(latitude_deg, longitude_deg, height_m) - origin) @ self._axes().T

    def geodetic(self, xyz) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(latitude deg, longitude deg, height m) of local points (..., 3)."""
        origin = ecef(self.latitude_deg, self.longitude_deg, self.height_m)
        return geodetic(np.asarray(xyz, dtype=float) @ self._axes() + origin)


def meridian_radius(latitude_rad):
    """R_M (m), the meridian's radius of curvature at geodetic latitude phi (rad):
    a (1 - e^2) / (1 - e^2 sin^2 phi)^(3/2); a latitude change d phi is R_M d phi metres north."""
    return WGS84_A * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * np.sin(latitude_rad) ** 2) ** 1.5


def transverse_radius(latitude_rad):
    """R_N (m), the prime vertical's radius of curvature at geodetic latitude phi (rad):
    a / sqrt(1 - e^2 sin^2 phi); a longitude change d lam is R_N cos phi d lam metres east."""
    return WGS84_A / np.sqrt(1.0 - WGS84_E2 * np.sin(latitude_rad) ** 2)
