"""Typed measurement records: what the pipeline gives the estimator (host.estimator), and
the products the estimator derives from them for the fusion tracks (host.tracks).

Records (:class:`Estimator.feed` takes one at a time, in time order as the pipeline merges
them; ``t`` is the host time base, seconds):

===========  ===========================================================================
ImuSample    one SINS sample: gyro (rad/s) and accel (m/s^2) in body axes (x forward,
             y left, z up); ``nd_ok`` False: the registers were not updated (a repeat);
             ``uptime_s`` on the first sample the host sees: how long the board has been
             up (its sample counter; a host that starts late sees it late)
Exchange     one ranging report of the anchors' gateway: ``distance`` (m) None when the
             exchange did not complete; rssi (dBm) and status as reported
MagSample    one magnetometer frame of the SINS stream: ``field`` (uT) in body axes, at the
             time of the sample frame it follows (same seq)
Restart      a device's clock began a new epoch (``device``: "imu" or "anchors");
             ``uptime_s``: how long the device has been up (the IMU's sample counter)
===========  ===========================================================================

Products (made once by the estimator, given to each track that takes them):

===========  ===========================================================================
Motion       the SINS's horizontal nav-frame acceleration as a linear measurement of the
             fusion state (``kind`` "accel"), or at rest while the alignment runs
             ("stationary")
Range        one corrected exchange distance as a range measurement (each exchange: the
             EKF/UKF take it with ``tight = "toa"``, 001's tc and fatci always)
Tdoa         one closed TDMA cycle's range differences to the reference anchor
             (``tight = "tdoa"``); ``meas`` None when too few anchors remain
Fix          a WSN position fix of a closed TDMA cycle (host.wsn.Solver)
FixRefused   a closed cycle that gave no fix, and why
===========  ===========================================================================

A new kind of measurement (RSSI, magnetometer, position fix, ...) is a new record here, a
branch of the pipeline that builds it, and the tracks that take it; the estimator passes
a record it does not process itself straight to those tracks.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True, slots=True)
class ImuSample:
    t: float
    gyro: Any  # 3 rad/s
    accel: Any  # 3 m/s^2
    nd_ok: bool = True
    uptime_s: float | None = None


@dataclass(frozen=True, slots=True)
class Exchange:
    t: float
    anchor: int
    distance: float | None
    rssi: int = 0
    status: int = 0x0F


@dataclass(frozen=True, slots=True)
class AnchorExchange:
    """An exchange between two anchors: ``anchor`` ranged ``other`` (the report's tag field
    holds an anchor's id) and heard it at ``rssi``; 003 eqs. 3-4 fit each anchor's path-loss
    parameters to these readings. The network's, so every vehicle's estimator gets it."""
    t: float
    anchor: int
    other: int
    distance: float | None
    rssi: int = 0
    status: int = 0x0F


@dataclass(frozen=True, slots=True)
class MagSample:
    t: float
    field: Any  # 3 uT, body axes


@dataclass(frozen=True, slots=True)
class Restart:
    t: float
    device: str
    uptime_s: float = 0.0


@dataclass(frozen=True, slots=True)
class Motion:
    t: float
    kind: str  # "accel" | "stationary"
    z: Any
    R: Any
    meas: Any  # host.filters.model.Linear


@dataclass(frozen=True, slots=True)
class Range:
    t: float
    z: Any
    R: Any
    meas: Any  # host.filters.model.Ranges


@dataclass(frozen=True, slots=True)
class Tdoa:
    t: float
    implausible: int  # anchors dropped: a difference beyond their separation
    z: Any = None
    R: Any = None
    meas: Any = None  # None: fewer than two differences remain
    fix: Any = None  # the Fix of the same cycle, if it gave one


@dataclass(frozen=True, slots=True)
class Fix:
    """A WSN position fix. ``cov`` is the 2x2 position covariance (CRLB at ``p``); ``dropped``:
    the anchors left out as outliers."""

    t: float
    p: Any  # 2, m
    cov: Any  # 2x2, m^2
    anchors: tuple[int, ...]
    chi2: float
    dropped: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class FixRefused:
    t: float
    reason: str
