"""The estimator's settings, declared once: the host config's [site], [vehicle] and [filters]
tables (their keys, units, defaults and checks on the schema, navtwin.common.schema) and the
:class:`EstimatorConfig` made of them, which is all an :class:`navtwin.host.estimator.Estimator`
is given.

Who reads what: the host config (host.config) builds these tables from its TOML file and
makes each vehicle's EstimatorConfig from them (:meth:`EstimatorConfig.of`); the estimator and
the tracks read the EstimatorConfig's fields by name (``cfg.alignment_s``, ``cfg.start``);
neither imports the other. The defaults that the emulated lab (emulator.scenario) shares
(site, alignment, x azimuth, gyro range, start) are written once in navtwin.common.lab.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from navtwin.common import lab
from navtwin.common.anchorgrid import WIDE_ANCHOR_IDS
from navtwin.common.limits import (ANCHOR_IDS, ELLIPSOID_HEIGHT_M, GRAVITY_M_S2, LATITUDE_DEG, LONGITUDE_DEG,
                                   MAX_COORD_M, MAX_HEIGHT_M, RANGE_SCALE)
from navtwin.common.schema import Check, between, build, each, key, one_of, plain, positive
from navtwin.protocols.adis16350 import GYRO_LSB_DPS

from . import imu_noise, tracks
from .calibration import Calibration

__all__ = ["EstimatorConfig", "Site", "Tuning", "Vehicle"]


def _hex16(v) -> bool:
    return len(v) == 16 and all(c in "0123456789abcdefABCDEF" for c in v)


@dataclass(frozen=True)
class Site:
    """The host config's [site]: where the lab is on the earth."""

    latitude_deg: float = key(lab.LATITUDE_DEG, "deg", "geodetic latitude of the lab", between(*LATITUDE_DEG))
    longitude_deg: float = key(lab.LONGITUDE_DEG, "deg", "east longitude of the area's origin "
                               "(x, y = 0, 0): places the estimates' lat, lon and 003's "
                               "geodetic tracks' area frame", between(*LONGITUDE_DEG))
    height_m: float = key(lab.HEIGHT_M, "m", "WGS-84 ellipsoid height of the area's origin (the "
                          "floor, z = 0)", between(*ELLIPSOID_HEIGHT_M))
    local_gravity: float = key(lab.LOCAL_GRAVITY, "m/s^2", "local gravity", between(*GRAVITY_M_S2))
    declination_deg: float = key(lab.DECLINATION_DEG, "deg", "magnetic declination, east of true "
                                 "north: turns a magnetometer heading to true (IGRF-13 at the lab)",
                                 between(-180, 180))


@dataclass(frozen=True)
class Vehicle:
    """The host config's [vehicle] (or one of its [[vehicles]]): where it stands at power-up,
    its tag and radio, its IMU's range."""

    start: tuple[float, float] = key(lab.START, "m", "where the vehicle stands at power-up",
                                     each(between(-MAX_COORD_M, MAX_COORD_M)))
    heading_deg: float = key(0.0, "deg", "initial heading, counter-clockwise from +x",
                             between(-360, 360))
    tag_height: float = key(0.0, "m", "tag above the anchors' z = 0 plane",
                            between(-MAX_HEIGHT_M, MAX_HEIGHT_M))
    tag: int | None = key(None, "", "only this tag id's exchanges are used", between(*WIDE_ANCHOR_IDS))
    router: str | None = key(None, "", "only this radio's SINS stream is used (SH+SL)",
                             Check(_hex16, "must be 16 hex digits (SH+SL)",
                                   'write it like "0013A20040A1B2D4"'))
    gyro_range_dps: int = key(lab.GYRO_RANGE_DPS, "deg/s", "ADIS16350 range set by SENS/AVG",
                              one_of(*GYRO_LSB_DPS))


@dataclass(frozen=True)
class Tuning:
    """The estimator's shared settings (the host config's [filters] keys; docs/host.md).
    Beyond their ranges the filters overflow (1e308), divide by zero or never finish
    (output_period_s 1e-300). The defaults are 000's office lab."""

    altitude_m: float = key(0.0, "m", "site altitude (gravity and earth rate)", between(-1000, 10000))
    x_azimuth_deg: float = key(lab.X_AZIMUTH_DEG, "deg", "azimuth of the area's +x, clockwise from north "
                               "(90: x east)", between(0, 360))
    alignment_s: float = key(lab.ALIGNMENT_S, "s", "stationary period from the board's power-up",
                             positive(hi=3600))
    output_period_s: float = key(0.1, "s", "estimates at k times this", between(0.001, 60))
    range_sigma_m: float = key(0.4, "m", "one exchange's distance, 1 sigma", positive(hi=100))
    range_scale: float = key(1.0, "", "f of 001: distance = (reported - c_i) / f",
                             between(*RANGE_SCALE))
    # the noise the 10 ms reads carry (host.imu_noise), not the datasheet's stated ARW
    arw_deg_rt_hr: float = key(imu_noise.ARW_DEG_RT_HR, "deg/sqrt(h)", "gyro angle random walk "
                               "of the ADIS16350's 10 ms reads", positive(hi=1000))
    gyro_bias_instability_dps: float = key(imu_noise.GYRO_BIAS_INSTABILITY_DPS, "deg/s", "gyro in-run bias stability "
                                           "(ADIS16350)", between(0, 100))
    # SINS acceleration as a measurement (docs/filters.md): sigma^2 = accel_sigma_m_s2^2 +
    # (tilt_inflation g s T)^2, s = the tilt rate the alignment leaves, T = time since it
    accel_sigma_m_s2: float = key(1.0, "m/s^2", "SINS acceleration measurement, 1 sigma",
                                  positive(hi=100))
    tilt_inflation: float = key(10.0, "", "growth of that sigma with the tilt error",
                                between(0, 1000))
    jerk_psd: float = key(0.5, "m^2/s^5", "constant-acceleration model's white jerk",
                          positive(hi=10000))
    p0_sigma: tuple[float, float, float] = key((0.2, 0.02, 0.1), "m, m/s, m/s^2",
                                               "initial position, velocity, acceleration sigma",
                                               each(positive(hi=100)))
    stationary_sigma: tuple[float, float] = key((0.01, 0.05), "m/s, m/s^2", "velocity, "
                                                "acceleration while aligning", each(positive(hi=100)))
    reinit_sigma: tuple[float, float] = key((1.0, 1.0), "m/s, m/s^2", "velocity, acceleration "
                                            "of a re-initialisation", each(positive(hi=100)))
    gate_probability: float = key(0.9999, "", "chi-square innovation gate",
                                  Check(lambda v: 0 < v < 1, "must be in (0, 1)", "use e.g. 0.9999"))
    gate_reopen_s: float = key(2.0, "s", "every update of one kind gated out this long: the "
                               "track is off", positive(hi=3600))
    extrapolated_after_s: float = key(0.5, "s", "no aiding for longer: an estimate is "
                                      "extrapolated", positive(hi=3600))
    imu_gap_s: float = key(0.5, "s", "a longer gap in the IMU stream is not bridged: the "
                           "fusion tracks start again from the next fix", positive(hi=3600))
    wsn_method: str = key("tdoa", "", "pure-WSN and KF fixes (000 eqs. 12-13)", one_of("toa", "tdoa"))
    reference_anchor: int = key(1, "", "TDOA reference (000 eq. 12), an anchor id",
                                between(*ANCHOR_IDS))
    cycle_s: float = key(0.1, "s", "TDMA cycle: exchanges grouped within this window",
                         between(0.001, 10))
    max_lag_s: float = key(0.5, "s", "oldest measurement a fusion track applies",
                           between(0, 60))
    max_range_m: float = key(100.0, "m", "longer distances are implausible",
                             positive(hi=MAX_COORD_M))
    fix_margin_m: float | None = key(2.0, "m", "WSN fixes beyond the anchors' box grown by "
                                     "this are refused", between(0, MAX_COORD_M))


#: The tables an EstimatorConfig is made of, in the order their fields come.
TABLES = (Site, Vehicle, Tuning)


@dataclass(frozen=True)
class EstimatorConfig(Tuning, Vehicle, Site):
    """Everything the estimator needs: the lab's [site], one [vehicle], the shared [filters]
    settings (its fields, by inheritance: declared once), the anchor survey, the tracks and
    their own settings. Checked when made: each table's keys by its schema (the tracks' own
    settings too), and what spans them (at least 3 anchors, known tracks)."""

    anchors: Mapping[int, tuple[float, ...]] = field(kw_only=True)  # id -> (x, y, z), m
    range_bias_m: Mapping[int, float] = field(default_factory=dict)  # c_i of 001: calibrated delays
    filters: tuple[str, ...] = tracks.DEFAULT
    settings: Mapping[str, object] = field(default_factory=dict)  # track name -> its Settings
    vehicle: int = 1  # which vehicle of the lab (host config): its estimates say so
    calibration: Calibration | None = None  # 001's f, c_i, sigma(d): replaces range_scale, range_bias_m

    @classmethod
    def of(cls, *tables: Site | Vehicle | Tuning, **rest) -> EstimatorConfig:
        """The EstimatorConfig made of *tables* (a host config's Site, one of its Vehicles,
        its Tuning) and the other fields *rest* (anchors, filters, ...)."""
        return cls(**{f.name: getattr(t, f.name) for t in tables for f in fields(t)}, **rest)

    def __post_init__(self):
        unknown = [f for f in self.filters if f not in tracks.BUILT_IN]
        if unknown:  # only then ask the registry and the entry points (a scan of sys.path)
            known = tracks.names()
            unknown = [f for f in unknown if f not in known]
        if unknown or not self.filters:
            known = tracks.names()
            raise ValueError(f"filters: unknown {unknown or 'empty list'}; use some of {','.join(known)}")
        for table in TABLES:  # each key's checks, as the host config's TOML gets them
            build(table, plain(self, table))
        for name, own in self.settings.items():  # and each track's own, its [filters.<name>]
            build(type(own), plain(own), (("filters", 0), (name, 0)))
            if hasattr(own, "check_config"):  # a track's keys that need other sections
                own.check_config(self)
        if len(self.anchors) < 3:
            raise ValueError(f"anchors: {len(self.anchors)} given; a 2-D fix needs at least 3, list them all")

    @property
    def heading_rad(self) -> float:
        """The initial heading in radians (MEMS gyros cannot gyrocompass: it is given)."""
        return math.radians(self.heading_deg)

    @property
    def tilt_rate_sigma(self) -> float:
        """rad/s: gyro bias error left by averaging ARW over the alignment, and the bias's
        in-run wander; the tilt error grows as this times the time since the alignment."""
        arw = math.radians(self.arw_deg_rt_hr) / 60.0  # rad/sqrt(s)
        return math.sqrt(arw**2 / self.alignment_s + math.radians(self.gyro_bias_instability_dps) ** 2)
