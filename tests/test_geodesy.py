"""common.geodesy: the local frame against formulas written independently of it (no geodesy
package is installed): Vincenty's inverse for the distance and azimuth on the ellipsoid, and
the tangent plane's known drop s^2 / (2 R)."""
import math

import numpy as np
import pytest

from navtwin.common.geodesy import LocalFrame, ecef, geodetic

A, F = 6378137.0, 1 / 298.257223563  # WGS-84 by its flattening, not common.earth's e^2


def vincenty(lat1, lon1, lat2, lon2):
    """Geodesic distance (m) and forward azimuth (deg) on WGS-84 (Vincenty 1975, inverse)."""
    b = A * (1 - F)
    u1, u2 = math.atan((1 - F) * math.tan(math.radians(lat1))), math.atan((1 - F) * math.tan(math.radians(lat2)))
    big_l = math.radians(lon2 - lon1)
    lam = big_l
    for _ in range(200):
        sl, cl = math.sin(lam), math.cos(lam)
        ss = math.hypot(math.cos(u2) * sl, math.cos(u1) * math.sin(u2) - math.sin(u1) * math.cos(u2) * cl)
        cs = math.sin(u1) * math.sin(u2) + math.cos(u1) * math.cos(u2) * cl
        sigma = math.atan2(ss, cs)
        sa = math.cos(u1) * math.cos(u2) * sl / ss
        c2a = 1 - sa * sa
        c2sm = cs - 2 * math.sin(u1) * math.sin(u2) / c2a
        c = F / 16 * c2a * (4 + F * (4 - 3 * c2a))
        prev, lam = lam, big_l + (1 - c) * F * sa * (sigma + c * ss * (c2sm + c * cs * (-1 + 2 * c2sm ** 2)))
        if abs(lam - prev) < 1e-13:
            break
    u_sq = c2a * (A * A - b * b) / (b * b)
    ka = 1 + u_sq / 16384 * (4096 + u_sq * (-768 + u_sq * (320 - 175 * u_sq)))
    kb = u_sq / 1024 * (256 + u_sq * (-128 + u_sq * (74 - 47 * u_sq)))
    ds = kb * ss * (c2sm + kb / 4 * (cs * (-1 + 2 * c2sm ** 2)
                                     - kb / 6 * c2sm * (-3 + 4 * ss ** 2) * (-3 + 4 * c2sm ** 2)))
    s = b * ka * (sigma - ds)
    az = math.atan2(math.cos(u2) * math.sin(lam),
                    math.cos(u1) * math.sin(u2) - math.sin(u1) * math.cos(u2) * math.cos(lam))
    return s, math.degrees(az) % 360


START_003 = (32.0, 118.0)
NODES_003 = [(32.0, 118.01), (32.01, 118.02), (32.02, 118.01), (32.01, 118.0)]
#: (origin, point): 003's nodes from its start, and two sites 1.4 km apart at other latitudes
PAIRS = [(START_003, node) for node in NODES_003] + [((34.306, 108.89), (34.316, 108.9)),
                                                      ((-60.01, -70.03), (-60.0, -70.02))]


@pytest.mark.parametrize("origin, point", PAIRS)
def test_local_plane_matches_vincenty(origin, point):
    """Over ~1-2.4 km the plane's horizontal distance is the geodesic's to a millimetre
    (they differ by s^3 / (6 R^2), under 0.1 mm), its bearing to 1e-5 deg (the geodesic
    leaves the origin along the plane's direction to the point), and a point on the
    ellipsoid lies s^2 / (2 R) below the plane."""
    (o_lat, o_lon), (lat, lon) = origin, point
    frame = LocalFrame(o_lat, o_lon, 0.0, 90.0)
    x, y, z = frame.local(lat, lon, 0.0)
    s, az = vincenty(o_lat, o_lon, lat, lon)
    assert math.hypot(x, y) == pytest.approx(s, abs=1e-3)
    bearing = math.degrees(math.atan2(x, y))
    assert (bearing - az + 180) % 360 - 180 == pytest.approx(0, abs=1e-5)
    phi = math.radians(o_lat)  # Gaussian mean radius at the origin
    r = A * math.sqrt(1 - (2 * F - F * F)) / (1 - (2 * F - F * F) * math.sin(phi) ** 2)
    assert z == pytest.approx(-s * s / (2 * r), rel=2e-2)


def test_azimuth_rotates_the_plane():
    """x at azimuth 0 is north, y west: (x, y) = (n, -e) of the azimuth-90 frame's (e, n)."""
    north = LocalFrame(32.0, 118.0, 0.0, 0.0).local(32.01, 118.01)
    east = LocalFrame(32.0, 118.0, 0.0, 90.0).local(32.01, 118.01)
    assert north == pytest.approx([east[1], -east[0], east[2]], abs=1e-9)


def test_round_trips():
    rng = np.random.default_rng(3)
    lat = rng.uniform(-89, 89, 500)
    lon = rng.uniform(-180, 180, 500)
    h = rng.uniform(-500, 9000, 500)
    back = geodetic(ecef(lat, lon, h))
    assert np.allclose(back[0], lat, atol=1e-10) and np.allclose(back[2], h, atol=1e-6)
    assert np.allclose((back[1] - lon + 180) % 360 - 180, 0, atol=1e-10)
    frame = LocalFrame(32.0, 118.0, 12.0, 30.0)
    xyz = rng.uniform(-3000, 3000, (500, 3))
    assert np.allclose(frame.local(*frame.geodetic(xyz)), xyz, atol=1e-6)
