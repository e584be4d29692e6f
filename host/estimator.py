"""The fusion core: measurement records in (host.measurements), one estimate per track per
output period out.

The tracks (host.tracks: ``sins``, ``wsn``, ``kf``, ``ekf``, ``ukf`` and any registered one)
are plug-ins; the Estimator names none of them. It is composed of parts with one job each:

* host.inertial.Inertial: the IMU stream's checks, the alignment, the strapdown, each
  sample's Motion product (the nav-frame acceleration as a measurement, or at rest while
  aligning) and the IMU's gaps;
* host.ranging.Ranging: the exchanges' checks and correction, their TDMA cycles, each
  cycle's fix (the last two kept) or FixRefused, the Range (each exchange) and Tdoa (each
  cycle) products;
* host.timebase.FilterTime: the filter time (the latest measurement's), the tracks with
  ``predicts`` predicted to it lazily, all at once, and when an estimate is extrapolated;
* host.tracks.base.TrackContext: what the tracks may see of all this, read-only;

and keeps the dispatch, device restarts, the output instants and the stats.

Each record and product goes to the tracks whose :meth:`Track.handlers` take its type, in
``cfg.filters`` order; a record type that the estimator does not process itself goes
straight to its takers (a new sensor needs no edit here). A product is made only when a
track takes it.

Time. A record's ``t`` is the measurement time (host time base, seconds). A measurement
older than the filter time (the two streams are merged by the caller) is applied with its
lag (host.tracks.fusion). The SINS needs its IMU samples strictly in order; an IMU sample
not after the previous one is rejected.

Output. Estimates are emitted at the instants k * output_period_s of the measurement time
base: an estimate at t_k reflects every measurement with t_s <= t_k. They are returned by
the :meth:`Estimator.feed` call that first passes t_k (nothing comes out before the first
measurement), one per configured track in ``cfg.filters`` order. The Estimator is a pure
function of its call sequence: no wall clock, no randomness.

Estimate fields: x, y (m), vx, vy (m/s) in the area frame; yaw (rad, 0 along area +x,
counter-clockwise) from the SINS attitude (the configured initial heading until alignment
ends), None for wsn; cov = the 4x4 covariance of (x, y, vx, vy), row-major, 16 floats.
``extrapolated``: the track's last aiding is more than ``extrapolated_after_s`` before t
(the configured start counts as aiding at the first measurement), or the track waits to
re-initialise.

Discontinuities (docs/filters.md). A restart (a device's clock began a new epoch) resets
every track (:meth:`Track.restart`) and, for the IMU, realigns the strapdown on the
stationary start, placed at the mean of the fixes during the alignment (the configured
start without any). Counted by track and cause in ``stats()["reinit"]``.
"""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace

from navtwin.common.limits import ANCHOR_IDS, MAX_COORD_M, RANGE_SCALE
from navtwin.common.schema import Check, between, build, each, key, one_of, positive
from navtwin.protocols.adis16350 import ARW_DEG_RT_HR, GYRO_BIAS_INSTABILITY_DPS

from . import tracks
from .calibration import Calibration
from .filters import ConstantAcceleration
from .inertial import Inertial
from .measurements import Exchange, Fix, FixRefused, ImuSample, Motion, Range, Restart, Tdoa
from .ranging import Ranging
from .timebase import FilterTime
from .tracks.base import Estimate, Track, TrackContext
from .wsn import AnchorLayout

__all__ = ["DEVICES", "Estimate", "Estimator", "EstimatorConfig", "Tuning"]

DEVICES = ("imu", "anchors")  # what can restart (a Restart record)


def _methods() -> Check:
    return one_of("toa", "tdoa")


@dataclass(frozen=True)
class Tuning:
    """The estimator's shared settings (the host config's [filters] keys; docs/host.md).
    Beyond their ranges the filters overflow (1e308), divide by zero or never finish
    (output_period_s 1e-300). The defaults are 000's office lab."""

    altitude_m: float = key(0.0, "m", "site altitude (gravity and earth rate)", between(-1000, 10000))
    x_azimuth_deg: float = key(90.0, "deg", "azimuth of the area's +x, clockwise from north "
                               "(90: x east)", between(0, 360))
    alignment_s: float = key(5.0, "s", "stationary period from the board's power-up",
                             positive(hi=3600))
    output_period_s: float = key(0.1, "s", "estimates at k times this", between(0.001, 60))
    range_sigma_m: float = key(0.4, "m", "one exchange's distance, 1 sigma", positive(hi=100))
    range_scale: float = key(1.0, "", "f of 001: distance = (reported - c_i) / f",
                             between(*RANGE_SCALE))
    arw_deg_rt_hr: float = key(ARW_DEG_RT_HR, "deg/sqrt(h)", "gyro angle random walk (ADIS16350)",
                               positive(hi=1000))
    gyro_bias_instability_dps: float = key(GYRO_BIAS_INSTABILITY_DPS, "deg/s", "gyro in-run bias stability "
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
    wsn_method: str = key("tdoa", "", "pure-WSN and KF fixes (000 eqs. 12-13)", _methods())
    tight: str = key("tdoa", "", "EKF/UKF range measurement: per cycle (tdoa) or each range "
                     "(toa)", _methods())
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


def _office_anchors() -> dict[int, tuple[float, float, float]]:
    """The office lab's survey, written once: in host/configs/office.toml."""
    from .config import load  # here: the config imports this module

    return dict(load("office").anchors)


@dataclass(frozen=True)
class EstimatorConfig(Tuning):
    """Everything the estimator needs: the shared settings, what the host config's other
    sections say (site, anchors, vehicle), the tracks and their own settings."""

    anchors: Mapping[int, tuple[float, ...]] = field(default_factory=lambda: _office_anchors())
    tag_height: float = 0.0  # m, same datum as the anchors' z
    latitude_deg: float = 34.316
    gravity: float = 9.7952  # m/s^2, local
    start: tuple[float, float] = (6.0, 1.8)  # m, where the vehicle rests during alignment
    heading0_rad: float = 0.0  # initial heading (MEMS gyros cannot gyrocompass)
    gyro_range_dps: int = 300  # ADIS16350 range: the service's word scale; counts overrange
    range_bias_m: Mapping[int, float] = field(default_factory=dict)  # c_i of 001: calibrated delays
    filters: tuple[str, ...] = tracks.DEFAULT
    settings: Mapping[str, object] = field(default_factory=dict)  # track name -> its Settings
    vehicle: int = 1  # which vehicle of the lab (host config): its estimates say so
    calibration: Calibration | None = None  # 001's f, c_i, sigma(d): replaces range_scale, range_bias_m

    def __post_init__(self):
        unknown = [f for f in self.filters if f not in tracks.BUILT_IN]
        if unknown:  # only then ask the registry and the entry points (a scan of sys.path)
            known = tracks.names()
            unknown = [f for f in unknown if f not in known]
        if unknown or not self.filters:
            known = tracks.names()
            raise ValueError(f"filters: unknown {unknown or 'empty list'}; use some of {','.join(known)}")
        # the schema's checks, the ones the host config applies (the same rule, once)
        build(Tuning, {f.name: list(v) if isinstance(v, tuple) else v for f in fields(Tuning)
                       if (v := getattr(self, f.name)) is not None})
        if len(self.anchors) < 3:
            raise ValueError(f"anchors: {len(self.anchors)} given; a 2-D fix needs at least 3, list them all")

    @property
    def tilt_rate_sigma(self) -> float:
        """rad/s: gyro bias error left by averaging ARW over the alignment, and the bias's
        in-run wander; the tilt error grows as this times the time since the alignment."""
        arw = math.radians(self.arw_deg_rt_hr) / 60.0  # rad/sqrt(s)
        return math.sqrt(arw**2 / self.alignment_s + math.radians(self.gyro_bias_instability_dps) ** 2)


class Estimator:
    """The fusion core (module docstring): records in, estimates out; dispatch, restarts,
    output instants and stats here, the rest in its parts ``inertial``, ``ranging``,
    ``time`` and the tracks' ``context``."""

    def __init__(self, cfg: EstimatorConfig | None = None):
        self.cfg = cfg = cfg or EstimatorConfig()
        self.layout = AnchorLayout(cfg.anchors, cfg.tag_height)
        self.calibration = cfg.calibration
        classes = [tracks.get(n) for n in cfg.filters]
        self.inertial = Inertial(cfg, need_sins=any(cls.uses_strapdown for cls in classes))
        self.ranging = Ranging(cfg, self.layout)
        self.time = FilterTime(cfg.output_period_s, cfg.extrapolated_after_s)
        # calibration None: the tracks were always built before the estimator held it, so
        # fatci has used sigma_poly_m even with one (a bug kept while issue 18 keeps the
        # estimates bit-identical; passing self.calibration fixes it)
        self.context = TrackContext(cfg, ConstantAcceleration(cfg.jerk_psd), self.layout, None,
                                    time=self.time, inertial=self.inertial, ranging=self.ranging,
                                    estimator=self)
        self.tracks: list[Track] = [cls(self.context, cfg.settings.get(n))
                                    for n, cls in zip(cfg.filters, classes)]
        self.time.predicting = [track for track in self.tracks if track.predicts]
        self._takers: dict[type, list] = {}  # record or product type -> its takers' handlers
        for track in self.tracks:
            for kind, handler in track.handlers().items():
                self._takers.setdefault(kind, []).append(handler)
        # record type -> (its part's check, its processing); other types: straight to takers
        self._own = {ImuSample: (self.inertial.accept, self._imu),
                     Exchange: (self.ranging.accept, self._exchange),
                     Restart: (self._restartable, self._restart)}
        # opt-in: fn(t, filter, kind, dim, nis, accepted) per gated fusion update (the NIS
        # the report draws); None costs the tracks one attribute test
        self.on_innovation: Callable | None = None
        self.input_rejections: Counter = Counter()  # restarts, other records: the parts count their own
        self.emitted: Counter = Counter()

    # ---------------------------------------------------------------- dispatch

    def feed(self, record) -> list[Estimate]:
        """One measurement record (host.measurements), in time order; the estimates of the
        output instants it passes. A record its part accepts: the instants before it, its
        processing, the tracks that take its type, the instants up to it."""
        accept, process = self._own.get(type(record)) or (self._acceptable, None)
        if not accept(record):
            return []
        t = record.t
        if self.time.t is None:  # the first measurement: everything starts
            self.time.start(t)
            for track in self.tracks:
                track.start(t)
        out = self._emit(t, through=False) if self.time.next_out < t else []
        self.time.advance(t)
        if process is not None:
            process(record)
        self._give(type(record), record)
        return out + self._emit(t, through=True) if self.time.next_out <= t else out

    def _give(self, kind: type, item) -> None:
        """A record or product to the tracks that take its kind, in output order."""
        for take in self._takers.get(kind, ()):
            take(item)

    def _imu(self, rec: ImuSample) -> None:
        if self.inertial.gap(rec.t):
            for track in self.tracks:
                track.gap(rec.t)
        acceleration = self.inertial.step(rec.t)
        if Motion in self._takers:  # a product is made only when a track takes it
            self._give(Motion, self.inertial.motion(rec.t, acceleration))

    def _exchange(self, rec: Exchange) -> None:
        d = self.ranging.distance(rec)
        if d is not None and Range in self._takers:
            self._give(Range, self.ranging.range(rec, d, self.time.t))
        for cycle in self.ranging.add(rec, d):
            self._cycle(cycle)

    def _cycle(self, cycle) -> None:
        """A closed TDMA cycle: its fix (the SINS origin after a restart, the tracks waiting
        to re-initialise, then the tracks that take fixes) or FixRefused, its Tdoa."""
        fix = self.ranging.fix(cycle)
        if isinstance(fix, FixRefused):
            self._give(FixRefused, fix)
            fix = None
        else:
            self.inertial.fix(fix)
            for track in self.tracks:
                track.offer_fix(fix)
            self._give(Fix, fix)
        if Tdoa in self._takers:
            self._give(Tdoa, self.ranging.tdoa(cycle, fix, self.time.t))

    def _restartable(self, rec: Restart) -> bool:
        if rec.device not in DEVICES:
            raise ValueError(f"device {rec.device!r}: use one of {', '.join(DEVICES)}")
        if math.isfinite(rec.t):
            return True
        self.input_rejections["restart_implausible"] += 1
        return False

    def _restart(self, rec: Restart) -> None:
        """``device`` (one of ``DEVICES``) restarted: its clock began a new epoch at t, so
        what the tracks hold need not be where the vehicle is: each track resets, no cycle
        spans it, and after an IMU restart the strapdown realigns (host.inertial)."""
        for track in self.tracks:
            track.restart(rec.device, rec.t)
        self.ranging.restart()
        if rec.device == "imu":
            self.inertial.restart(rec.t, rec.uptime_s)

    def _acceptable(self, rec) -> bool:
        """A record the estimator does not process goes straight to the tracks that take it."""
        if type(rec) not in self._takers:
            raise TypeError(f"no track takes {type(rec).__name__} records; enable one that does")
        if math.isfinite(rec.t):
            return True
        self.input_rejections[f"{type(rec).__name__}_implausible"] += 1
        return False

    # ---------------------------------------------------------------- output instants

    def _emit(self, t: float, through: bool) -> list[Estimate]:
        """The estimates of the output instants before t (``through``: up to t inclusive)."""
        out = []
        while (b := self.time.next_out) < t or (through and b == t):
            sins = self.inertial.sins
            yaw = sins.yaw if sins is not None else self.cfg.heading0_rad
            for track in self.tracks:
                e = track.estimate(b, yaw)
                if e is not None:
                    out.append(e if e.vehicle == self.cfg.vehicle else
                               replace(e, vehicle=self.cfg.vehicle))
                    self.emitted[track.name] += 1
            self.time.next_instant()
        return out

    # ---------------------------------------------------------------- stats

    @property
    def reinit_count(self) -> int:
        """Every re-initialisation so far: one int to watch for a new one."""
        return sum(sum(track.reinits.values()) for track in self.tracks)

    def imu_gaps(self) -> dict:
        """IMU gaps so far: ``bridged`` (the state kept) and ``reinit`` (the tracks restarted)."""
        return self.inertial.gaps()

    def stats(self) -> dict:
        """Counts: inputs, input rejections, updates and rejections per aided track by
        kind/reason, estimates emitted, re-initialisations, and the alignment result."""
        rejections = self.inertial.rejections + self.ranging.rejections + self.input_rejections
        return {
            "imu_samples": self.inertial.counts["samples"],
            "imu_overrange": self.inertial.counts["overrange"],
            "imu_gaps": self.imu_gaps(),
            "exchanges": self.ranging.exchanges,
            "input_rejections": dict(sorted(rejections.items())),
            "updates": {t.name: dict(sorted(t.updates.items())) for t in self.tracks if t.aided},
            "rejections": {t.name: dict(sorted(t.rejections.items())) for t in self.tracks if t.aided},
            "estimates": {t.name: self.emitted[t.name] for t in self.tracks},
            "reinit": {t.name: dict(sorted(t.reinits.items())) for t in self.tracks if t.reinits},
            "reinit_pending": [t.name for t in self.tracks if t.pending],
            "alignment": self.inertial.stats(),
        }
