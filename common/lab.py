"""The lab's defaults: what the emulated lab (emulator.scenario) and the lab computer
(host.settings) take when a scenario or a host config does not say, written once so that the
two agree where they mean the same thing.

The site is 000's lab (latitude 34.316 deg) with standard gravity; each shipped scenario and
host config states its own site (local gravity 9.7952 m/s^2) and start, so these are what a
new lab's file starts from.
"""
from navtwin.common import geomagnetic
from navtwin.protocols.adis16350 import STANDARD_GRAVITY

#: deg, geodetic latitude of the site: it projects the earth rate (000's lab).
LATITUDE_DEG = 34.316
#: deg, east longitude of the site: 000 gives none; 34.316 N is Xi'an's latitude, so its
#: longitude (it places the earth's magnetic field, common.geomagnetic)
LONGITUDE_DEG = 108.9
#: m, WGS-84 ellipsoid height of the site (the area's floor at its origin): 000 gives none;
#: 0 keeps the earth's field at the ellipsoid, where the magnetometer first took it
HEIGHT_M = 0.0
#: decimal year of the earth's magnetic field (IGRF-13's epoch)
FIELD_EPOCH = 2020.0
#: deg, magnetic declination (east of true north) at the site: IGRF-13's, which the
#: emulated magnetometer senses and the host's heading corrects for (-3.90 deg)
DECLINATION_DEG = round(geomagnetic.declination_deg(LATITUDE_DEG, LONGITUDE_DEG,
                                                    year=FIELD_EPOCH), 2)
#: m/s^2, local gravity where the site's is not surveyed: the standard value.
LOCAL_GRAVITY = STANDARD_GRAVITY
#: deg, azimuth (clockwise from north) of the area's +x: 90, x east and y north.
X_AZIMUTH_DEG = 90.0
#: s, how long the vehicle stands still after the IMU's power-up (the alignment).
ALIGNMENT_S = 5.0
#: deg/s, the ADIS16350's gyro range (SENS/AVG): its power-up setting.
GYRO_RANGE_DPS = 300
#: m, where the vehicle stands at power-up: the area's origin.
START = (0.0, 0.0)
