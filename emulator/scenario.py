"""Scenarios: the emulated lab as a TOML file, validated on load.

``load_scenario("office")`` loads a shipped scenario (emulator/scenarios/<name>.toml);
``load_scenario("path/x.toml")`` loads a file. A file may start from another scenario with
``base = "office"`` (a shipped name or a path relative to the file) and override any key;
tables merge key by key, arrays of tables are replaced whole. A bad file raises
:class:`ScenarioError` with ONE line naming the file, the key, the problem and the fix.
Every key, its unit and default: docs/scenarios.md (the table there is generated from the
declarations below by :func:`schema_markdown`).

Frames. Navigation frame n: local level, x and y are the area's coordinates (the +x axis
points at azimuth ``area.x_azimuth_deg``, 90 = east, so by default x east, y north), z up,
origin on the floor. Body frame b: x forward, y left, z up. Attitude: yaw, pitch, roll
(Z-Y-X, right-handed rotations about the body axes); yaw 0 = body x along +x,
counter-clockwise positive; a level vehicle reads +g on the z accelerometer. On the earth,
n is the tangent plane at the site (``[site]`` latitude, longitude, height: the local origin),
so an anchor may also be given in degrees (common.geodesy converts, exactly, through ECEF).
"""
from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from navtwin.protocols.adis16350 import GYRO_LSB_DPS, POWER_UP_FILTER_TAPS
from navtwin.protocols import ports
from navtwin.protocols.ports import NANOLOC, SINS, XBEE
from navtwin.protocols.xbee import BAUD_CODES, baud_rate
from navtwin.common import geomagnetic, lab
from navtwin.common.anchorgrid import WIDE_ANCHOR_IDS, AnchorGrid, expand
from navtwin.common.geodesy import LocalFrame
from navtwin.common.limits import (ANCHOR_IDS, ELLIPSOID_HEIGHT_M, GRAVITY_M_S2, LATITUDE_DEG, LONGITUDE_DEG,
                              MAX_COORD_M, MAX_DURATION_S, MAX_HEIGHT_M, RANGE_BIAS_M, RANGE_SCALE, NETWORKS, SEEDS, VEHICLES,
                              limit_problem)

from . import shipped, trajectory as geometry
from .faults import Fault
from .imu_errors import GRADES, ImuErrors, override_keys, profile
from .imu_words import DEFAULT_WORDS, WORDS
from .rng import stream, vehicles_name
from .tdma import SCHEDULES as TDMA_SCHEDULES
from navtwin.common import tomlfile
from navtwin.common.schema import (REQUIRED, Check, Invalid, between, build, dump, each, key, markdown_table,
                     non_negative, one_of, positive)

SCENARIO_DIR, SCENARIO_NAMES = shipped.DIR, shipped.NAMES

BAUDS = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400)


#: The devices run in blocks of this much true time (world.py); the IMU model needs a sample
#: in every block, so its sample period must not be longer.
BLOCK_S = 1.0
SMPL_TIME_BASES_S = (1.0 / 1638.4, 18.921e-3)  # ADIS16350 SMPL_PRD bit 7 = 0, 1


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message is one line naming the fix (a newline in
    a path or value it quotes is shown as ``\\n``)."""

    def __init__(self, message: str) -> None:
        super().__init__(message.replace("\n", "\\n"))


def _ppm(doc: str):
    return key(0.0, "ppm", doc, between(-200, 200))


@dataclass(frozen=True)
class Site:
    latitude_deg: float = key(lab.LATITUDE_DEG, "deg", "geodetic (WGS-84) latitude of the area's local "
                              "origin (x, y = 0, 0): projects the earth rate", between(*LATITUDE_DEG))
    longitude_deg: float = key(lab.LONGITUDE_DEG, "deg", "east longitude of the local origin: places "
                               "the earth's field and geodetic anchors", between(*LONGITUDE_DEG))
    height_m: float = key(lab.HEIGHT_M, "m", "WGS-84 ellipsoid height of the local origin (the floor, "
                          "z = 0)", between(*ELLIPSOID_HEIGHT_M))
    local_gravity: float = key(lab.LOCAL_GRAVITY, "m/s^2", "local gravity magnitude (with centrifugal part)",
                               between(*GRAVITY_M_S2, "use the local gravity, about 9.78 to 9.83"))


@dataclass(frozen=True)
class Area:
    size: tuple[float, float] = key(REQUIRED, "m", "extent along x and y; anchors and waypoints lie inside",
                                    each(positive("give a positive width and depth", hi=MAX_COORD_M)))
    origin: tuple[float, float] = key((0.0, 0.0), "m", "the corner with the smallest x and y",
                                      each(between(-MAX_COORD_M, MAX_COORD_M)))
    x_azimuth_deg: float = key(lab.X_AZIMUTH_DEG, "deg", "azimuth (clockwise from north) of +x; 90 = x east, y north",
                               between(0, 360))

    def contains(self, x: float, y: float) -> bool:
        return (self.origin[0] <= x <= self.origin[0] + self.size[0]
                and self.origin[1] <= y <= self.origin[1] + self.size[1])


@dataclass(frozen=True)
class Anchor:
    """An anchor placed in the area's local frame (x, y, optional z) or geodetically (lat_deg,
    lon_deg, optional height_m; common.geodesy places it in the local frame): one or the other."""

    id: int = key(REQUIRED, "", "anchor id in the gateway reports", between(*ANCHOR_IDS))
    x: float | None = key(None, "m", "antenna position x (local; or give lat_deg, lon_deg)",
                          between(-MAX_COORD_M, MAX_COORD_M))
    y: float | None = key(None, "m", "antenna position y (local)", between(-MAX_COORD_M, MAX_COORD_M))
    z: float | None = key(None, "m", "antenna height; none = the tag's height (a planar layout)",
                          between(-MAX_HEIGHT_M, MAX_HEIGHT_M))
    lat_deg: float | None = key(None, "deg", "antenna latitude (WGS-84; instead of x, y)",
                                between(*LATITUDE_DEG))
    lon_deg: float | None = key(None, "deg", "antenna east longitude (with lat_deg)",
                                between(*LONGITUDE_DEG))
    height_m: float | None = key(None, "m", "antenna ellipsoid height (with lat_deg); none = the "
                                 "tag's height (a planar layout)", between(*ELLIPSOID_HEIGHT_M))
    ppm: float = _ppm("crystal offset of this anchor's clock (times tau1, tau4)")
    range_bias_m: float = key(0.0, "m", "c_i of 001 eq. 13: this anchor's constant range bias",
                              between(*RANGE_BIAS_M))

    def __post_init__(self):
        local, geo = (self.x, self.y), (self.lat_deg, self.lon_deg)
        if local == geo == (None, None):
            raise Invalid("x", "and y, or lat_deg and lon_deg, must be given; place the anchor with one pair")
        if local != (None, None) and geo != (None, None):
            raise Invalid("lat_deg", "and lon_deg go without x and y; place the anchor with one pair")
        for pair, names in ((local, ("x", "y")), (geo, ("lat_deg", "lon_deg"))):
            if pair != (None, None) and None in pair:
                raise Invalid(names[pair.index(None)], "is missing; give both coordinates of the pair")
        if None not in local and self.height_m is not None:
            raise Invalid("height_m", "goes with lat_deg and lon_deg; with x and y give z")
        if None not in geo and self.z is not None:
            raise Invalid("z", "goes with x and y; with lat_deg and lon_deg give height_m")


@dataclass(frozen=True)
class Tag:
    id: int = key(16, "", "tag id in the gateway reports (above 254: wide reports, type 02)",
                  between(*WIDE_ANCHOR_IDS))
    z: float = key(0.3, "m", "tag antenna height above the floor; the vehicle's truth z",
                   non_negative(hi=MAX_HEIGHT_M))
    ppm: float = _ppm("crystal offset of the tag's clock (times tau2, tau3)")


@dataclass(frozen=True)
class Trajectory:
    waypoints: tuple[tuple[float, float], ...] = key(
        REQUIRED, "m", "corners of the taped line; the first is the start, the first leg the start heading")
    speed_m_s: float = key(REQUIRED, "m/s", "cruising speed along the line", positive("set a positive speed up to 100 m/s", hi=100))
    closed: bool = key(True, "", "the line is a closed loop (it must run straight through the start)")
    loops: int = key(1, "", "laps of a closed loop before the vehicle stops", between(1, 1000))
    alignment_s: float = key(lab.ALIGNMENT_S, "s", "stationary alignment period at the start",
                              non_negative(hi=MAX_DURATION_S))
    accel_m_s2: float = key(0.2, "m/s^2", "peak acceleration of the smooth start and stop",
                            positive("set a positive acceleration up to 100 m/s^2", hi=100))
    turn_radius_m: float = key(1.0, "m", "radius of the circular part of each turn",
                               positive("set a positive turn radius", hi=MAX_COORD_M))
    transition_m: float = key(0.5, "m", "length of the clothoid entering and leaving each turn "
                              "(continuous curvature)", non_negative(hi=MAX_COORD_M))
    step_m: float = key(0.0, "m", "move this far, then rest dwell_s, and so on (001's calibration "
                        "walk); 0 = drive without stopping", non_negative(hi=MAX_COORD_M))
    dwell_s: float = key(2.5, "s", "rest after each step_m move", positive(hi=MAX_DURATION_S))

    def __post_init__(self):
        n = len(self.waypoints)
        if n < (3 if self.closed else 2):
            raise Invalid("waypoints", f"needs at least {3 if self.closed else 2} points for "
                                       f"{'a closed loop' if self.closed else 'a line'} (got {n}); add waypoints")
        pts = self.waypoints + ((self.waypoints[0],) if self.closed else ())
        for i, (a, b) in enumerate(zip(pts, pts[1:])):
            if math.dist(a, b) < 1e-6:
                raise Invalid("waypoints", f"{i + 1} and {i + 2} coincide; remove one of them")
        if not self.closed and self.loops != 1:
            raise Invalid("loops", f"must be 1 for an open line (got {self.loops}); "
                                   "set closed = true or loops = 1")
        if self.closed:
            (x0, y0), (x1, y1), (xl, yl) = pts[0], pts[1], pts[-2]
            cross = (x0 - xl) * (y1 - y0) - (y0 - yl) * (x1 - x0)
            dot = (x0 - xl) * (x1 - x0) + (y0 - yl) * (y1 - y0)
            if abs(cross) > 1e-9 * math.dist(pts[0], pts[-2]) * math.dist(pts[0], pts[1]) or dot <= 0:
                raise Invalid("waypoints", "of a closed loop must pass straight through the first "
                                           "waypoint (the start); put the start on a straight "
                                           "leg between the last and the second waypoint")
        path = geometry.Path(self.waypoints, self.closed, self.turn_radius_m, self.transition_m)
        if not self.step_m:  # a stepped walk needs no room to ramp up to speed
            geometry.SpeedProfile(self.alignment_s, self.speed_m_s, self.accel_m_s2,
                                  path.length * self.loops)


#: ``[imu] grade`` and every field of the grade's error profile, settable one by one
#: (emulator.imu_errors: the profile's fields, units and checks are declared there once)
ImuGrade = dataclasses.make_dataclass("ImuGrade", [
    ("grade", str, key("adis16350", "", "IMU error profile by name (emulator.imu_errors.GRADES); the keys "
                       "below override its fields", one_of(*GRADES))),
    *((name, float | None, f) for name, f in override_keys().items())], frozen=True)


@dataclass(frozen=True)
class Imu(ImuGrade):
    words: str | None = key(None, "", "the gyro and accelerometer words the board reads and sends "
                            "(emulator.imu_words): adis16350 = 14-bit, in sample frames (type 01); "
                            "adis16488 = 32-bit X_GYRO_OUT:LOW pairs, +-450 deg/s, in wide sample "
                            "frames (type 03), fine enough for a navigation-grade IMU; none = "
                            f"{DEFAULT_WORDS}, the lab's", one_of(*WORDS))
    gyro_range_dps: int = key(lab.GYRO_RANGE_DPS, "deg/s", "SENS/AVG bits 10:8: gyro dynamic range "
                              "of the adis16350 words (the adis16488 words' is +-450)",
                              one_of(*sorted(GYRO_LSB_DPS)))
    filter_taps: int = key(POWER_UP_FILTER_TAPS, "", "SENS/AVG bits 2:0 = log2(N): Bartlett window taps N",
                           one_of(1, 2, 4, 8, 16, 32, 64))
    smpl_prd: int = key(1, "", "SMPL_PRD: internal sample period 0.61035 ms x (NS+1) (bit 7 = 18.921 ms "
                        "time base); 1 = 819.2 SPS", between(1, 255))
    temperature_c: float = key(25.0, "degC", "sensor temperature (X/Y/ZTEMP_OUT)", between(-40, 85))
    temperature_noise_c: float = key(0.15, "degC", "1 sigma noise of each temperature word",
                                     non_negative(hi=100))
    supply_v: float = key(5.0, "V", "supply voltage (SUPPLY_OUT; outside 4.75..5.25 V sets EA)",
                          between(4.0, 6.0))
    supply_noise_v: float = key(0.002, "V", "1 sigma noise of the supply word",
                                non_negative(hi=1))

    def __post_init__(self):
        # every error field resolved from the grade: the scenario as run (to_toml, a
        # recording's scenario.toml) states the values, so it replays the same after a
        # grade's figures change
        for name, value in dataclasses.asdict(GRADES[self.grade]).items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        need = {150: 4, 75: 16}.get(self.gyro_range_dps, 1)
        if self.filter_taps < need:
            raise Invalid("filter_taps", f"must be >= {need} at gyro_range_dps = {self.gyro_range_dps} "
                                         f"(got {self.filter_taps}; datasheet Table 21); "
                                         f"set filter_taps = {need} or more")
        if self.sample_period_s > BLOCK_S:
            raise Invalid("smpl_prd", f"{self.smpl_prd} gives a sample period of "
                                      f"{self.sample_period_s:g} s, longer than the emulator's "
                                      f"{BLOCK_S:g} s generation block; use smpl_prd <= "
                                      f"{_slowest_smpl_prd()}")

    @property
    def word_format(self):
        """The words' kind (emulator.imu_words): ``words``, or the lab's when none is set."""
        return WORDS[self.words or DEFAULT_WORDS]

    @property
    def errors(self) -> ImuErrors:
        """The grade's error profile with the fields this table sets."""
        return profile(self.grade, {f.name: getattr(self, f.name) for f in dataclasses.fields(ImuErrors)})

    @property
    def sample_period_s(self) -> float:
        base = SMPL_TIME_BASES_S[self.smpl_prd >> 7]
        return base * ((self.smpl_prd & 0x7F) + 1)


def _slowest_smpl_prd() -> int:
    """The largest SMPL_PRD whose sample period fits in BLOCK_S (time base bit 7 set)."""
    return 0x80 + int(BLOCK_S / SMPL_TIME_BASES_S[1]) - 1


@dataclass(frozen=True)
class Board:
    baud: int = key(SINS.baud, "bit/s", "the DSP board's RS-232 rate (8N1)", one_of(*BAUDS))
    period_ms: float = key(10.0, "ms", "frame period in the board's own clock", between(1, 1000))
    start_ms: float = key(1.0, "ms", "true time of the first frame", non_negative(hi=1_000_000))
    spi_read_us: float = key(500.0, "us", "the registers are read this long before a frame is written",
                             between(0, 5000))


    def __post_init__(self):
        if self.spi_read_us > self.start_ms * 1e3:
            raise Invalid("start_ms", f"{self.start_ms:g} ms is before the first SPI read ends "
                                      f"(spi_read_us {self.spi_read_us:g}); set start_ms >= "
                                      f"{self.spi_read_us / 1e3:g}")


def _soft_iron_ok(m) -> bool:
    """A soft-iron matrix the host can still read a heading through: det > 0.1 (not
    singular, no reflection)."""
    (a, b, c), (d, e, f), (g, h, i) = m
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0.1


@dataclass(frozen=True)
class Magnetometer:
    """The vehicle's three-axis magnetometer (emulator.magnetometer), read by the DSP board
    and sent as magnetometer frames in its SINS stream; absent or ``enabled = false``: none."""

    enabled: bool = key(False, "", "the board reads a magnetometer and sends its frames")
    rate_hz: float = key(10.0, "Hz", "frames per second, one after every Nth sample frame (N "
                         "= the board's frame rate / rate_hz, a whole number)",
                         positive("use a rate that divides the board's frame rate, e.g. 10", hi=1000))
    noise_ut: float = key(0.2, "uT", "1 sigma white noise per axis (HMC5883L: 2 mG noise floor)",
                          non_negative(hi=100))
    hard_iron_ut: tuple[float, float, float] = key(
        (0.0, 0.0, 0.0), "uT", "the vehicle's own field in body axes (added after soft iron)",
        each(between(-200, 200)))
    soft_iron: tuple[tuple[float, float, float], tuple[float, float, float],
                     tuple[float, float, float]] = key(
        ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), "",
        "rows of the 3x3 matrix S in m = S b + h + noise (identity = no soft iron)",
        Check(lambda m: all(-2 <= v <= 2 for row in m for v in row) and _soft_iron_ok(m),
              "must be a matrix with elements from -2 to 2 and a determinant above 0.1",
              "write a near-identity matrix, e.g. [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"))
    year: float = key(lab.FIELD_EPOCH, "", "decimal year of the earth's field (IGRF-13 and its "
                      "predicted secular variation)", between(*geomagnetic.EPOCHS))


@dataclass(frozen=True)
class Clocks:
    board_ppm: float = _ppm("DSP board crystal: the 10 ms frame schedule")
    imu_ppm: float = _ppm("ADIS16350 internal sample clock")
    network_ppm: float = _ppm("the anchors' shared wired clock: TDMA schedule and report t_us")


@dataclass(frozen=True)
class Multipath:
    """eps of 001 eq. 13 (emulator.multipath): per anchor, a field over the tag's position
    plus a Gauss-Markov drift; off unless ``enabled``."""

    enabled: bool = key(False, "", "add the NLOS/multipath error eps to every range")
    field_sigma_m: float = key(0.12, "m", "1 sigma of the position-dependent part (per anchor)",
                               non_negative(hi=10))
    corr_length_m: float = key(1.5, "m", "its correlation length L: exp(-r^2 / (2 L^2))",
                               positive(hi=MAX_COORD_M))
    features: int = key(64, "", "random Fourier features of that field", between(1, 4096))
    drift_sigma_m: float = key(0.08, "m", "1 sigma of the time-varying part (per anchor)",
                               non_negative(hi=10))
    drift_corr_s: float = key(10.0, "s", "its correlation time (first-order Gauss-Markov)",
                              positive(hi=1e9))


@dataclass(frozen=True)
class Ranging:
    cycle_ms: float = key(100.0, "ms", "TDMA cycle: every anchor (in-range: every one in range at "
                          "its start) ranges the tag once per cycle",
                          between(1, 10000))
    slot_ms: float = key(25.0, "ms", "slot length; anchor number i of slot_order starts at i x slot",
                         positive(hi=10000))
    slot_order: tuple[int, ...] = key((), "", "anchor ids in slot order; empty = the [[anchors]] order")
    start_ms: float = key(5.0, "ms", "network time of the first cycle", non_negative(hi=1_000_000))
    scale: float = key(1.0, "", "f of 001 eq. 13: range scale factor", between(*RANGE_SCALE))
    sigma0_m: float = key(0.1, "m", "range noise sigma(d) = sigma0_m + sigma_per_m x d",
                          non_negative(hi=100))
    sigma_per_m: float = key(0.01, "m/m", "growth of the range noise with distance (001 sect. 3)",
                             non_negative(hi=1))
    tag_reply_us: float = key(100.0, "us", "tag's reply delay, its own clock (tau2 nominal)",
                              between(1, 4000))
    anchor_reply_us: float = key(100.0, "us", "anchor's reply delay, its own clock (tau4 nominal)",
                                 between(1, 4000))
    reply_jitter_ns: float = key(20.0, "ns", "1 sigma jitter of each reply delay",
                                 non_negative(hi=1_000_000))
    leg_gap_us: float = key(300.0, "us", "from the end of the first round trip to the tag's second "
                            "packet", non_negative(hi=1_000_000))
    result_us: float = key(800.0, "us", "from the end of the second round trip to the result at the "
                           "anchor (tag sends tau2, tau3)", non_negative(hi=1_000_000))
    timeout_ms: float = key(6.0, "ms", "an anchor gives up on a silent tag after this (status 0x40)",
                            positive(hi=10000))
    timeout_prob: float = key(0.0, "", "probability that an exchange times out at random",
                              between(0, 1))
    rssi_1m_dbm: float = key(-45.0, "dBm", "RSSI(1 m) of 003 eq. 1", between(-120, 20))
    path_loss_exponent: float = key(2.0, "", "n of 003 eq. 1", between(1, 6))
    shadowing_db: float = key(2.0, "dB", "sigma of the log-normal shadowing of 003 eq. 1",
                          non_negative(hi=100))
    radio_range_m: float | None = key(None, "m", "the gateway reports an exchange only when the "
                                      "tag is this close to the anchor; none = unlimited",
                                      positive(hi=MAX_COORD_M))
    anchor_exchange_every_cycles: int = key(0, "", "every Nth cycle (the first, N + 1st, "
                                            "...) the anchors range one another instead of the "
                                            "tag, each the next in slot order in turn (003 eqs. "
                                            "3-4's readings; reported with the other anchor's id "
                                            "as the tag); 0 = never", between(0, 1_000_000))
    # unset, these two keys are not written by to_toml: the scenarios from before them keep their text
    schedule: str | None = key(None, "", "TDMA schedule (emulator.tdma): slots = each anchor of "
                               "slot_order its slot in every cycle; in-range = at each cycle start "
                               "the anchors within radio_range_m of the tag take the cycle's slots, "
                               "nearest first (a field of hundreds of anchors, 004); none = slots",
                               one_of(*TDMA_SCHEDULES))
    cycle_jitter_ms: float | None = key(None, "ms", "1 sigma of each cycle start's offset on the "
                                        "anchors' network clock (004 eq. 2.2's sampling-time error; "
                                        "clipped to (cycle_ms - slot_ms) / 2); none = 0",
                                        non_negative(hi=10000))
    multipath: Multipath = Multipath()
    network: str | None = key(None, "", "with several vehicles: shared = one TDMA ranges every tag, "
                              "cycle c the tag of vehicle 1 + c mod N (each tag's rate falls as "
                              "tags are added), one gateway port; per-vehicle = a network of the "
                              "same anchors per vehicle, each its own gateway port (nanoloc2 ...) "
                              "and random streams; none = shared", one_of(*NETWORKS))

    def __post_init__(self):
        if len(set(self.slot_order)) != len(self.slot_order):
            raise Invalid("slot_order", "lists an anchor twice; list each anchor id once")
        if self.tdma == "in-range" and self.radio_range_m is None:
            raise Invalid("radio_range_m", "is needed with schedule = \"in-range\" (the anchors in "
                                           "range take the slots); set the radio range in m")
        if self.tdma == "in-range" and (self.slot_order or self.anchor_exchange_every_cycles):
            raise Invalid("schedule", "\"in-range\" gives the slots by distance, without slot_order "
                                      "or anchor exchanges; remove them or use schedule = \"slots\"")
        exchange_us = max(self.timeout_ms * 1e3, self.tag_reply_us + self.anchor_reply_us
                          + self.leg_gap_us + self.result_us)
        if exchange_us >= self.slot_ms * 1e3:
            raise Invalid("slot_ms", f"{self.slot_ms:g} ms is too short for an exchange "
                                     f"({exchange_us / 1e3:g} ms with its timeout); lengthen the "
                                     "slots or shorten timeout_ms")

    @property
    def tdma(self) -> str:
        """The schedule's name (emulator.tdma.SCHEDULES)."""
        return self.schedule or "slots"


@dataclass(frozen=True)
class Gateway:
    baud: int = key(NANOLOC.baud, "bit/s", "the gateway's serial line (8N1)", one_of(*BAUDS))
    latency_us: float = key(200.0, "us", "anchor result to gateway (wired)",
                              non_negative(hi=1_000_000))


@dataclass(frozen=True)
class Link:
    latency_ms: float = key(3.0, "ms", "fixed part of the one-way delay (radio processing at both ends)",
                            non_negative(hi=10000))
    jitter_ms: float = key(2.24, "ms", "random CSMA backoff per attempt, uniform in [0, jitter_ms]",
                           non_negative(hi=10000))
    per_attempt_loss: float = key(0.01, "", "probability that one transmission attempt is lost",
                                  between(0, 1))
    max_retries: int = key(3, "", "MAC retries after a lost attempt; after them the packet is lost",
                           between(0, 15))
    retry_ms: float = key(0.864, "ms", "ACK wait before a retry", non_negative(hi=10000))


def _radio(sl: int, ni: str, vr: int, ap: int, extra: dict | None = None):
    """The fields shared by both radios, with this radio's defaults."""
    return {
        "SH": key(0x0013A200, "", "serial number high", between(0, 0xFFFFFFFF), hex=8),
        "SL": key(sl, "", "serial number low", between(0, 0xFFFFFFFF), hex=8),
        "NI": key(ni, "", "node identifier", Check(lambda v: len(v) <= 20 and v.isascii() and v.isprintable(),
                                                    "must be <= 20 printable ASCII characters",
                                                    "shorten it to printable ASCII")),
        "HV": key(0x1E46, "", "hardware version (XBee-PRO S2B)", between(0, 0xFFFF), hex=4),
        "VR": key(vr, "", "firmware version", between(0, 0xFFFF), hex=4),
        "AP": key(ap, "", "API mode (0 = transparent)",
                  one_of(1, 2) if ap else one_of(0, fix="the router is transparent: set AP = 0")),
        "BD": key(7, "", "interface rate code (7 = 115200)", one_of(*range(len(BAUD_CODES)))),
        **(extra or {}),
    }


def _table(name: str, fields: dict):
    """A frozen table class from ``{name: key(...)}``, fields in the given order."""
    return dataclasses.make_dataclass(
        name, [(n, type(f.default), f) for n, f in fields.items()], frozen=True)


Coordinator = _table("Coordinator", _radio(0x40A1B2C3, "LAB-COORD", 0x21A7, 2))
Router = _table("Router", _radio(0x40A1B2D4, "SINS-ROUTER", 0x22A7, 0, {
    "NP": key(84, "bytes", "maximum RF payload per packet", between(1, 84)),
    "RO": key(3, "chars", "packetisation timeout: character times of silence that end a packet",
              between(0, 255)),
}))


@dataclass(frozen=True)
class XBee:
    coordinator: Coordinator = Coordinator()
    router: Router = Router()
    network: str | None = key(None, "", "with several vehicles: shared = every vehicle's router "
                              "joins the one coordinator (its UART and transmit buffer carry "
                              "them all; what does not fit is dropped and counted); per-vehicle = "
                              "a coordinator, network and port (xbee2 ...) per vehicle; none = "
                              "shared", one_of(*NETWORKS))


@dataclass(frozen=True)
class Vehicle:
    """One vehicle: its taped line, nanoLOC tag, ADIS16350 on its DSP board, XBee router.

    A ``[[vehicles]]`` table holds these tables (``[vehicles.trajectory]``, ...); without
    one, the top-level tables of the same names are vehicle 1, and a ``[[vehicles]]`` entry
    is read into them (so a scenario writes, and runs, the same either way).
    """

    trajectory: Trajectory = key(REQUIRED, "", "")
    tag: Tag = Tag()
    imu: Imu = Imu()
    board: Board = Board()
    router: Router = Router()
    magnetometer: Magnetometer | None = key(None, "", "")


#: a [[vehicles]] table -> the top-level key path it stands for (vehicle 1)
VEHICLE_KEYS = {"trajectory": ("trajectory",), "tag": ("tag",), "imu": ("imu",),
                "board": ("board",), "router": ("xbee", "router"),
                "magnetometer": ("magnetometer",)}
MAX_VEHICLES = VEHICLES[1]


@dataclass(frozen=True, kw_only=True)
class Scenario:
    """A validated scenario. Sections are the TOML tables; see the module docstring."""

    name: str = key(REQUIRED, "", "scenario name")
    description: str = key("", "", "one line shown by tools")
    duration_s: float = key(REQUIRED, "s", "length of the run",
                      between(0.001, MAX_DURATION_S, f"set a duration from 0.001 to {MAX_DURATION_S} s"))
    seed: int = key(0, "", "default seed of the run's random streams", between(*SEEDS))
    site: Site = Site()
    area: Area = key(REQUIRED, "", "")
    anchors: tuple[Anchor, ...] = key((), "", "")
    anchor_grids: tuple[AnchorGrid, ...] | None = key(None, "", "")
    tag: Tag = Tag()
    trajectory: Trajectory = key(REQUIRED, "", "")
    imu: Imu = Imu()
    board: Board = Board()
    clocks: Clocks = Clocks()
    ranging: Ranging = Ranging()
    gateway: Gateway = Gateway()
    link: Link = Link()
    xbee: XBee = XBee()
    magnetometer: Magnetometer | None = key(None, "", "")
    #: vehicles 2, 3, ... (the top-level tables are vehicle 1; the loader's doc); none given:
    #: not written by to_toml, so one-vehicle scenarios keep their text
    vehicles: tuple[Vehicle, ...] | None = key(None, "", "")
    faults: tuple[Fault, ...] = ()

    def __post_init__(self):
        ids = [a.id for a in self.anchors]
        if not ids and not self.grids:
            raise Invalid("anchors", "is empty; add at least one [[anchors]] or [[anchor_grids]] table")
        seen: set[int] = set()
        for i, a in enumerate(ids):
            if a in seen:
                raise Invalid(f"[[anchors]] #{i + 1} id", f"{a} is used by another anchor; give every "
                                                          "anchor its own id")
            seen.add(a)
        expand(self.grids)  # the grids' ids among themselves
        for k, g in enumerate(self.grids):
            if clash := seen.intersection(g.ids):
                raise Invalid(f"[[anchor_grids]] #{k + 1} first_id", f"reuses anchor id {min(clash)} of "
                                                                      "[[anchors]]; give the grid its own id range")
            if not all(self.area.contains(x, y) for x, y in (g.box[:2], g.box[2:])):
                raise Invalid(f"[[anchor_grids]] #{k + 1} count", f"the grid spans {g.box} m, beyond the "
                                                                   "area; shrink the grid or enlarge [area]")
        self._check_fleet()
        for i, a in enumerate(self.anchors):
            x, y, _ = self.anchor_position(a)
            if not self.area.contains(x, y):
                x, y = round(x, 3) + 0.0, round(y, 3) + 0.0  # as a message shows them (no -0)
                raise Invalid(f"[[anchors]] #{i + 1} x", f"({x:g}, {y:g}) m is outside the area; "
                                                          "move the anchor or enlarge [area]")
        for a in self.ranging.slot_order:
            if a not in self.anchor_ids:
                raise Invalid("[ranging] slot_order", f"names anchor {a}, which is not in [[anchors]] "
                                                      "or [[anchor_grids]]; list only anchor ids")
        if self.ranging.tdma == "slots" and self.ranging.slot_ms * len(self.slot_order) > self.ranging.cycle_ms:
            raise Invalid("[ranging] slot_ms", f"x {len(self.slot_order)} anchors exceeds cycle_ms "
                                               f"{self.ranging.cycle_ms:g}; shorten the slots")
        for i, f in enumerate(self.faults):
            if (problem := self.fault_problem(f)) is not None:
                raise Invalid(f"[[faults]] #{i + 1} {problem[0]}", problem[1])

    def _check_fleet(self) -> None:
        """Each vehicle's own rules, and that no two share a tag id or a router address."""
        tags, addresses = {}, {}
        for n, v in enumerate(self.fleet, 1):
            at = (lambda table: f"[{table}]") if n == 1 else \
                (lambda table, n=n: f"vehicle {n} [{table.replace('xbee.', '')}]")
            if v.tag.id in self.anchor_ids:
                raise Invalid(f"{at('tag')} id", f"{v.tag.id} is also an anchor id; give the tag its own id")
            if v.tag.id in tags:
                raise Invalid(f"{at('tag')} id", f"{v.tag.id} is vehicle {tags[v.tag.id]}'s tag too; "
                                                 "give each vehicle's tag its own id")
            tags[v.tag.id] = n
            address = (v.router.SH, v.router.SL)
            if address in addresses:
                raise Invalid(f"{at('xbee.router')} SL", f"{v.router.SL:#X} with SH {v.router.SH:#X} "
                                                         f"is vehicle {addresses[address]}'s router "
                                                         "too; give each router its own SL")
            addresses[address] = n
            for i, (x, y) in enumerate(v.trajectory.waypoints):
                if not self.area.contains(x, y):
                    raise Invalid(f"{at('trajectory')} waypoints", f"{i + 1} ({x:g}, {y:g}) m is outside "
                                                                   "the area; move it or enlarge [area]")
            mag = v.magnetometer
            if mag is not None and mag.enabled:
                every = 1000.0 / v.board.period_ms / mag.rate_hz
                if every < 1 - 1e-9 or abs(every - round(every)) > 1e-9:
                    raise Invalid(f"{at('magnetometer')} rate_hz", f"{mag.rate_hz:g} does not divide the "
                                                                   f"board's {1000 / v.board.period_ms:g} "
                                                                   "frames/s; use a rate that does, e.g. 10")
            if baud_rate(v.router.BD) != v.board.baud:
                raise Invalid(f"{at('xbee.router')} BD", f"{baud_rate(v.router.BD)} bit/s differs from "
                                                         f"the board's {v.board.baud}; match [board] baud")

    def fault_problem(self, f) -> tuple[str, str] | None:
        """The part fault *f* names that this scenario lacks, as (setting, problem), or None:
        the one rule for the scenario's [[faults]], --fault and live faults."""
        if getattr(f, "anchor", None) is not None and f.anchor not in self.anchor_ids:
            return "anchor", f"{f.anchor} is not in [[anchors]] or [[anchor_grids]]; name an anchor id"
        n = len(self.fleet)
        has = f"vehicles 1 to {n}" if n > 1 else "vehicle 1 only"
        if getattr(f, "vehicle", None) is not None and not 1 <= f.vehicle <= n:
            return "vehicle", f"{f.vehicle}: the scenario has {has}; name one of its vehicles"
        if f.ACTS_ON == "coordinator" and f.vehicle > self.units("coordinator"):
            return "vehicle", (f"{f.vehicle}: the vehicles share one coordinator ([xbee] network); "
                               "use vehicle 1")
        port = getattr(f, "port", None)
        # a vehicle's instance (sins3) that this lab lacks; a package's own port is the lab's
        if port is not None and ports.known(port) and ports.parse(port)[1] > self.units(ports.get(port).unit):
            return "port", (f"{port}: the scenario has {has} and its ports are "
                            f"{', '.join(self.ports)}; name one of them")
        return None

    # -- derived views ---------------------------------------------------------------------
    @functools.cached_property
    def all_anchors(self) -> tuple[Anchor, ...]:
        """Every anchor: the [[anchors]] tables, then the nodes of each [[anchor_grids]] table
        (common.anchorgrid), in id order within a grid."""
        return self.anchors + tuple(Anchor(id=i, x=x, y=y, z=z) for i, x, y, z in expand(self.grids))

    @property
    def grids(self) -> tuple[AnchorGrid, ...]:
        """The [[anchor_grids]] tables (none given: written so by to_toml, no empty array)."""
        return self.anchor_grids or ()

    @functools.cached_property
    def anchor_ids(self) -> frozenset[int]:
        return frozenset(a.id for a in self.all_anchors)

    @property
    def slot_order(self) -> tuple[int, ...]:
        return self.ranging.slot_order or tuple(a.id for a in self.all_anchors)

    @property
    def frame(self) -> LocalFrame:
        """The area's local frame on the earth (common.geodesy)."""
        return LocalFrame.of(self.site, self.area)

    def anchor_position(self, anchor: Anchor) -> tuple[float, float, float]:
        """The antenna's local (x, y, z), m: as given, or its geodetic position in the local
        frame; no height given = the tag's height."""
        if anchor.lat_deg is None:
            return anchor.x, anchor.y, self.tag.z if anchor.z is None else anchor.z
        height = self.site.height_m if anchor.height_m is None else anchor.height_m
        x, y, z = (float(v) for v in self.frame.local(anchor.lat_deg, anchor.lon_deg, height))
        return x, y, self.tag.z if anchor.height_m is None else z

    @property
    def fleet(self) -> tuple[Vehicle, ...]:
        """Every vehicle in order: vehicle 1 (the top-level tables), then :attr:`vehicles`."""
        return (Vehicle(self.trajectory, self.tag, self.imu, self.board, self.xbee.router,
                        self.magnetometer), *(self.vehicles or ()))

    def units(self, unit: str) -> int:
        """How many of *unit* (a port's, protocols.ports) the lab has: a vehicle's, one per
        vehicle; the coordinator and the gateway, one per vehicle when the scenario gives each
        vehicle its own network, else one."""
        per_vehicle = {"vehicle": True, "coordinator": self.xbee.network == "per-vehicle",
                       "gateway": self.ranging.network == "per-vehicle"}
        return len(self.fleet) if per_vehicle.get(unit, False) else 1

    @property
    def duration_ns(self) -> int:
        return round(self.duration_s * 1e9)

    @functools.cached_property
    def ports(self) -> dict:
        """Serial settings of the ports the emulated lab exposes, by instance name
        (protocols.ports: ``sins``, then vehicle n's ``sins<n>`` ...), vehicle by vehicle."""
        c = self.xbee.coordinator
        own = {SINS.name: lambda v: {"baud": v.board.baud},
               XBEE.name: lambda v: {"baud": baud_rate(c.BD), "api_mode": c.AP},
               NANOLOC.name: lambda v: {"baud": self.gateway.baud}}
        return {name: own[p.name](self.fleet[ports.parse(name)[1] - 1])
                for name, p in self.instances() if p.name in own}

    def instances(self, vehicles=None) -> list[tuple[str, ports.Port]]:
        """(instance name, declaration) of every port of the cars *vehicles* (numbers; default
        all), car by car in the lab's order: a car's own ports, and the coordinator's and
        gateway's once, or once a car with networks of its own (:meth:`units`)."""
        cars = range(1, len(self.fleet) + 1) if vehicles is None else vehicles
        return [(ports.instance(p.name, n), p) for n in cars for p in ports.listed()
                if n <= self.units(p.unit)]

    @property
    def radios(self) -> dict:
        """AT values of the coordinator and the router (router MY joined with :attr:`seed`)."""
        return self.radios_for(self.seed)

    def routers_for(self, seed: int) -> tuple[dict, ...]:
        """AT values of each vehicle's router for a run with *seed*, in vehicle order."""
        return tuple(self.radios_for(seed, n)["router"] for n in range(1, len(self.fleet) + 1))

    def radios_for(self, seed: int, vehicle: int = 1) -> dict:
        """AT values of vehicle *vehicle*'s router and its coordinator for a run with *seed*:
        the network the coordinator formed (OP, OI, CH) and the router's MY come from the
        seed, as on a real join (vehicle n > 1: its MY from the stream "vehicle<n>.xbee.join",
        and, with per-vehicle networks, its coordinator's network too)."""
        def joined(n: int):
            rng = stream(seed, vehicles_name(n, "xbee.join"))
            my, oi = (int(v) for v in rng.integers(0x0001, 0xFFF8, size=2))  # 0xFFF8.. reserved
            op = int(rng.integers(1, 2**63))
            ch = int(rng.integers(0x0B, 0x1B))
            return my, {"OP": op, "OI": oi, "CH": ch, "ID": 0}
        my, network = joined(vehicle)
        if vehicle > 1 and self.xbee.network != "per-vehicle":
            network = joined(1)[1]  # it joined vehicle 1's coordinator
        coord = dataclasses.asdict(self.xbee.coordinator) | network | {"MY": 0x0000}
        router = dataclasses.asdict(self.fleet[vehicle - 1].router) | network | {"MY": my}
        return {"coordinator": coord, "router": router}

    def to_toml(self) -> str:
        """The scenario exactly as run, every key written; :func:`load_scenario` reads it back."""
        return dump(self)


def schema_markdown() -> str:
    """The table of every key (docs/scenarios.md carries it verbatim)."""
    return markdown_table(Scenario)


# -- loading ------------------------------------------------------------------------------
def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _resolve(ref: str, relative_to: Path | None) -> Path:
    if ref in SCENARIO_NAMES:
        return SCENARIO_DIR / f"{ref}.toml"
    path = Path(ref)
    if relative_to is not None and not path.is_absolute():
        path = relative_to / path
    try:
        if path.is_file():
            return path
    except OSError as e:  # a name too long for the file system, say (found by fuzzing)
        raise ScenarioError(f"scenario path {str(path)[:80]}...: {e.strerror}; check the path") \
            from None
    if path.suffix == ".toml" or len(path.parts) > 1:
        raise ScenarioError(f"no scenario file {path}; check the path")
    names = ", ".join(SCENARIO_NAMES)
    raise ScenarioError(f"unknown scenario '{ref}'; use one of {names} or the path of a .toml file")


def _read(path: Path, chain: tuple[Path, ...] = ()) -> dict:
    if path.resolve() in chain:
        raise ScenarioError(f"{path.name}: base chain loops back to {path.name}; remove the loop")
    data = tomlfile.read(path, ScenarioError, path.name)
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ScenarioError(f"{path.name}: base must be a scenario name or path in quotes; "
                            'write e.g. base = "office"')
    return _merge(_read(_resolve(base, path.parent), chain + (path.resolve(),)), data)


def _vehicles(data: dict, source: str) -> dict:
    """*data* (its ``base`` chain merged) with its ``[[vehicles]]`` tables read as the
    vehicles they stand for. With a top-level ``[trajectory]`` the top-level tables are
    vehicle 1 and every ``[[vehicles]]`` table is one more; without one, ``[[vehicles]]`` #1
    is read into the top-level tables (VEHICLE_KEYS; a table set in both places is refused)
    and the rest are vehicles 2, 3, .... A further vehicle starts from vehicle 1's tables and
    overrides them key by key."""
    vehicles = data.get("vehicles")
    if vehicles is None:
        return data
    if not isinstance(vehicles, list) or not all(isinstance(v, dict) for v in vehicles):
        raise ScenarioError(f"{source}: vehicles must be an array of tables; write each vehicle "
                            "as [[vehicles]]")
    for n, vehicle in enumerate(vehicles, 1):
        if unknown := [name for name in vehicle if name not in VEHICLE_KEYS]:
            raise ScenarioError(f"{source}: [[vehicles]] #{n} has an unknown key '{unknown[0]}'; "
                                f"known keys: {', '.join(VEHICLE_KEYS)}")
    out = {k: v for k, v in data.items() if k != "vehicles"}
    first_at_top = "trajectory" in out
    if len(vehicles) + first_at_top > MAX_VEHICLES:
        raise ScenarioError(f"{source}: the scenario has {len(vehicles) + first_at_top} vehicles; "
                            f"this version runs up to {MAX_VEHICLES}; remove [[vehicles]] tables")
    if not first_at_top and vehicles:
        for name, value in vehicles[0].items():
            *parents, leaf = VEHICLE_KEYS[name]
            table = out
            for p in parents:
                if not isinstance(table.get(p, {}), dict):
                    raise ScenarioError(f"{source}: {p} must be a table; write it as [{p}]")
                table[p] = dict(table.get(p, {}))
                table = table[p]
            if leaf in table:
                top = ".".join(VEHICLE_KEYS[name])
                raise ScenarioError(f"{source}: [{top}] is set at the top level and in "
                                    f"[[vehicles]] #1; keep one of them")
            table[leaf] = value
        vehicles = vehicles[1:]
    first = {}  # vehicle 1's tables, where the top level gives them
    for name, (*parents, leaf) in VEHICLE_KEYS.items():
        table = out
        for p in parents:
            table = table.get(p, {}) if isinstance(table.get(p, {}), dict) else {}
        if leaf in table:
            first[name] = table[leaf]
    if vehicles:
        out["vehicles"] = [_merge(first, v) for v in vehicles]
    return out


def load_scenario(ref: str | Path) -> Scenario:
    """A shipped scenario by name, or a scenario file by path; ScenarioError (one line) if bad."""
    path = _resolve(str(ref), None)
    return parse_scenario(_read(path), path.name)


def parse_scenario(data: dict, source: str = "scenario") -> Scenario:
    """Validate a parsed TOML dict (``base`` already resolved); *source* names it in errors."""
    try:
        return build(Scenario, _vehicles(data, source))
    except Invalid as e:
        raise ScenarioError(f"{source}: {e}".replace("\n", " ")) from None


def parse_fault(spec: str, where: str = "fault:") -> dict:
    """``KIND:key=value,...`` (the ``--fault`` option, ``navtwin ctl fault``) as the table a
    ``[[faults]]`` entry is; values are TOML scalars (``0.5``, ``true``, ``"text"``), a bare
    word a string."""
    kind, _, rest = spec.partition(":")
    if not kind.strip():
        raise ScenarioError(f"{where} {spec!r}: no kind; write KIND:key=value,... e.g. "
                            "byte_drop:port=sins,probability=0.01")
    table: dict = {"kind": kind.strip()}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        name, eq, text = item.partition("=")
        if not eq or not name.strip():
            raise ScenarioError(f"{where} {spec!r}: {item!r} is not key=value; write e.g. "
                                "start_s=1.5")
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # a bare word: port=sins, direction=to_device
        except (ValueError, RecursionError) as e:  # tomllib's limits: an integer's digits, nesting
            raise ScenarioError(f"{where} {name.strip()[:40]}: {limit_problem(e)}; shorten "
                                "it") from None
        table[name.strip()] = value
    return table


def with_faults(sc: Scenario, specs) -> Scenario:
    """*sc* with the faults of ``--fault`` *specs* after its own, validated as [[faults]]."""
    faults = list(sc.faults)
    for spec in specs:
        try:
            faults.append(build(Fault, parse_fault(spec), (("faults", len(faults) + 1),)))
            sc = dataclasses.replace(sc, faults=tuple(faults))
        except Invalid as e:
            raise ScenarioError(f"fault: {spec}: {e}".replace("\n", " ")) from None
    return sc
