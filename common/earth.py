"""The earth as both sides model it: the emulator's IMU senses its rotation, the host's
strapdown removes it (000 sect. 3.3); its WGS-84 ellipsoid places the site, the anchors and
the earth's field (common.geodesy, common.geomagnetic)."""

EARTH_RATE = 7.2916e-5  # rad/s, sidereal rotation rate
#: WGS-84 semi-major axis (m) and first eccentricity squared
WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3
