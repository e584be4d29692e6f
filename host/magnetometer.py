"""Heading from a magnetometer: the vehicle's yaw from the field it measures (003 sect. 3.2
takes it as the measurement psi_magnetometer of eq. 24).

Frames as the estimator's: area (navigation) frame x, y, z up with +x at azimuth A
(``x_azimuth_deg``, clockwise from true north); body x forward, y left, z up; yaw
counter-clockwise from +x, C_nb = Rz(yaw) Ry(pitch) Rx(roll). Tilt compensation levels
the measured field m with the roll and pitch::

    h = Ry(pitch) Rx(roll) m          (the field in the yawed, level frame)

whose horizontal part points at magnetic north, which lies at A - D counter-clockwise
from +x (D the declination, east positive). So::

    yaw = (A - D) - atan2(h_y, h_x)

Level (roll = pitch = 0) h = m. Errors: a noise of sigma per axis gives a yaw error of
about sigma / B_h (B_h the horizontal field); a hard iron H (body, horizontal) one of
up to asin(H / B_h), varying with the heading over a turn; a soft iron scaling x and y by
1 +- k one of up to asin(k) at twice the heading's frequency (tests/host/test_magnetometer.py
checks all three against emulated runs). The hard and soft iron are not calibrated here.
"""
from __future__ import annotations

import math


def yaw_from_field(field, declination_deg: float, x_azimuth_deg: float,
                   roll: float = 0.0, pitch: float = 0.0) -> float:
    """Yaw (rad, counter-clockwise from the area's +x, in (-pi, pi]) of a body whose
    magnetometer reads *field* (3, any unit), tilt-compensated with *roll* and *pitch* (rad)."""
    mx, my, mz = field
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    # Rx(roll) then Ry(pitch): body -> yawed level frame
    y1, z1 = cr * my - sr * mz, sr * my + cr * mz
    hx, hy = cp * mx + sp * z1, y1
    yaw = math.radians(x_azimuth_deg - declination_deg) - math.atan2(hy, hx)
    return math.atan2(math.sin(yaw), math.cos(yaw))
