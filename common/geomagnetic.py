"""The earth's magnetic field as both sides model it: the emulator's magnetometer senses it,
the host's heading takes its declination (docs/emulator-models.md, "Magnetometer").

Model: IGRF-13 (Alken et al. 2021, Earth Planets Space 73:49), its full degree-13
spherical-harmonic expansion, coefficients from the published table (``igrf13.txt``:
2020.0 and the predicted 2025.0, linear in between, the IGRF's own rule). With the
reference radius a = 6371.2 km, geocentric colatitude theta, east longitude phi, radius r
and P_n^m the Schmidt semi-normalised associated Legendre functions::

    V = a sum_n (a/r)^(n+1) sum_m (g_nm cos m phi + h_nm sin m phi) P_n^m(cos theta)
    X (north) = sum_n (a/r)^(n+2) sum_m (g cos + h sin) dP_n^m/dtheta
    Y (east)  = sum_n (a/r)^(n+2) sum_m m (g sin m phi - h cos m phi) P_n^m / sin theta
    Z (down)  = -sum_n (n+1) (a/r)^(n+2) sum_m (g cos + h sin) P_n^m

(B = -grad V), then rotated from the geocentric to the geodetic vertical (WGS-84). The
P_n^m and their theta-derivatives come from the standard recursions:
P_n^n = sqrt((2n-1)/(2n)) sin theta P_(n-1)^(n-1) (P_1^1 = sin theta) and
P_n^m = [(2n-1) cos theta P_(n-1)^m - sqrt((n-1)^2 - m^2) P_(n-2)^m] / sqrt(n^2 - m^2).
Checked in tests against ppigrf (an independent implementation of the same table) at
the lab and at 003's start; there are no singularities off the geographic poles
(|latitude| < 89.9 deg is all a scenario uses).
"""
from __future__ import annotations

import math
from functools import cache
from pathlib import Path

from navtwin.common.earth import WGS84_A, WGS84_E2

#: m, the reference radius of the IGRF
REFERENCE_RADIUS = 6371.2e3
#: the epochs of the coefficient table; a date outside them is refused by the scenario keys
EPOCHS = (2020.0, 2025.0)
DEGREE = 13

_TABLE = Path(__file__).with_name("igrf13.txt")


@cache
def _coefficients() -> dict[tuple[int, int], tuple[float, float]]:
    """(n, m) -> (value at 2020.0, value at 2025.0); m < 0 holds h(n, -m)."""
    out = {}
    for line in _TABLE.read_text().splitlines():
        if line and not line.startswith("#"):
            n, m, a, b = line.split()
            out[int(n), int(m)] = float(a), float(b)
    return out


def _gh(year: float):
    """g[n][m], h[n][m] at decimal *year* (linear between the table's epochs)."""
    w = (year - EPOCHS[0]) / (EPOCHS[1] - EPOCHS[0])
    g = [[0.0] * (DEGREE + 1) for _ in range(DEGREE + 1)]
    h = [[0.0] * (DEGREE + 1) for _ in range(DEGREE + 1)]
    for (n, m), (a, b) in _coefficients().items():
        (g if m >= 0 else h)[n][abs(m)] = a + w * (b - a)
    return g, h


def _legendre(theta: float):
    """Schmidt semi-normalised P[n][m](cos theta) and dP[n][m]/dtheta, n, m <= DEGREE."""
    c, s = math.cos(theta), math.sin(theta)
    p = [[0.0] * (DEGREE + 1) for _ in range(DEGREE + 1)]
    dp = [[0.0] * (DEGREE + 1) for _ in range(DEGREE + 1)]
    p[0][0] = 1.0
    for n in range(1, DEGREE + 1):
        k = 1.0 if n == 1 else math.sqrt((2 * n - 1) / (2 * n))
        p[n][n] = k * s * p[n - 1][n - 1]
        dp[n][n] = k * (c * p[n - 1][n - 1] + s * dp[n - 1][n - 1])
        for m in range(n):
            root = math.sqrt(n * n - m * m)
            back = math.sqrt((n - 1) ** 2 - m * m) if n - 2 >= m else 0.0
            p2, dp2 = (p[n - 2][m], dp[n - 2][m]) if n - 2 >= m else (0.0, 0.0)
            p[n][m] = ((2 * n - 1) * c * p[n - 1][m] - back * p2) / root
            dp[n][m] = ((2 * n - 1) * (c * dp[n - 1][m] - s * p[n - 1][m]) - back * dp2) / root
    return p, dp


def field_ned(latitude_deg: float, longitude_deg: float, height_m: float = 0.0,
              year: float = EPOCHS[0]) -> tuple[float, float, float]:
    """(north, east, down) main field in uT at a geodetic position and decimal year."""
    lat, lon = math.radians(latitude_deg), math.radians(longitude_deg)
    n_e = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)  # prime vertical radius
    rho = (n_e + height_m) * math.cos(lat)
    zeta = (n_e * (1.0 - WGS84_E2) + height_m) * math.sin(lat)
    r = math.hypot(rho, zeta)
    lat_c = math.atan2(zeta, rho)
    theta = math.pi / 2 - lat_c
    g, h = _gh(year)
    p, dp = _legendre(theta)
    x = y = z = 0.0
    for n in range(1, DEGREE + 1):
        scale = (REFERENCE_RADIUS / r) ** (n + 2)
        for m in range(n + 1):
            cm, sm = math.cos(m * lon), math.sin(m * lon)
            q = g[n][m] * cm + h[n][m] * sm
            x += scale * q * dp[n][m]
            y += scale * m * (g[n][m] * sm - h[n][m] * cm) * p[n][m]
            z -= scale * (n + 1) * q * p[n][m]
    y /= math.sin(theta)
    d = lat_c - lat  # the geocentric vertical leans by d from the geodetic one
    north = x * math.cos(d) - z * math.sin(d)
    down = x * math.sin(d) + z * math.cos(d)
    return north * 1e-3, y * 1e-3, down * 1e-3


def declination_deg(latitude_deg: float, longitude_deg: float, height_m: float = 0.0,
                    year: float = EPOCHS[0]) -> float:
    """Magnetic declination (deg, east of true north positive)."""
    north, east, _ = field_ned(latitude_deg, longitude_deg, height_m, year)
    return math.degrees(math.atan2(east, north))


def inclination_deg(latitude_deg: float, longitude_deg: float, height_m: float = 0.0,
                    year: float = EPOCHS[0]) -> float:
    """Magnetic inclination (dip, deg, down positive)."""
    north, east, down = field_ned(latitude_deg, longitude_deg, height_m, year)
    return math.degrees(math.atan2(down, math.hypot(north, east)))
