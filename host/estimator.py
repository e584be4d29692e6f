"""The fusion core: measurement records in (host.measurements), one estimate per track per
output period out.

The tracks (host.tracks: ``sins``, ``wsn``, ``kf``, ``ekf``, ``ukf`` and any registered one)
are plug-ins; the Estimator names none of them. It keeps what they share, and dispatches:

* the time base: ``t`` (the filter time, the latest measurement's) and ``t_predicted``
  (the fusion tracks are predicted to the filter time lazily, all at once: :meth:`sync`);
* the output instants k * output_period_s;
* the alignment and the strapdown (``sins``, ``aligned``), and from them each IMU sample's
  Motion product (the nav-frame acceleration as a measurement, or at rest while aligning);
* the WSN: exchanges grouped into TDMA cycles, each cycle's fix (``fixes``: the last two)
  or FixRefused, and the Range (each exchange, for the tracks that take it) and Tdoa
  (``tight = "tdoa"``) products;
* device restarts (Restart records): each track's reset, the strapdown's realignment, and
  the re-initialisation of the tracks waiting for a fix newer than their discontinuity.

Each record and product goes to the tracks whose :meth:`Track.handlers` take its type, in
``cfg.filters`` order; a record type that the estimator does not process itself goes
straight to its takers (a new sensor needs no edit here).

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

import numpy as np

from navtwin.common.limits import ANCHOR_IDS, MAX_COORD_M, RANGE_SCALE
from navtwin.common.schema import Check, between, build, each, key, one_of, positive
from navtwin.protocols.adis16350 import ARW_DEG_RT_HR, GYRO_BIAS_INSTABILITY_DPS
from navtwin.protocols import sins as sins_format
from navtwin.protocols.nanoloc import STATUS_TIMEOUT, is_complete

from . import tracks
from .calibration import Calibration
from .filters import ACCELERATION, ConstantAcceleration, Linear, Ranges
from .measurements import Exchange, FixRefused, ImuSample, Motion, Range, Restart, Tdoa
from .sins import Alignment, AlignmentResult, Strapdown
from .tracks.base import Estimate, Track, TrackContext
from .wsn import AnchorLayout, CycleGrouper, Fix, Solver, tdoa_covariance

__all__ = ["DEVICES", "Estimate", "Estimator", "EstimatorConfig", "Tuning"]

DEVICES = ("imu", "anchors")  # what can restart (a Restart record)

#: At rest: velocity and acceleration are zero (used while the alignment runs).
STATIONARY = Linear(np.hstack([np.zeros((4, 2)), np.eye(4)]))


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
    def __init__(self, cfg: EstimatorConfig | None = None):
        self.cfg = cfg = cfg or EstimatorConfig()
        self.layout = AnchorLayout(cfg.anchors, cfg.tag_height)
        self.model = ConstantAcceleration(cfg.jerk_psd)
        self.solver = Solver(self.layout, cfg.range_sigma_m, cfg.wsn_method, cfg.reference_anchor,
                             cfg.gate_probability, cfg.fix_margin_m)
        self.grouper = CycleGrouper(len(self.layout.ids), cfg.cycle_s)
        self.calibration = cal = cfg.calibration
        # None, not cal: the tracks were always built before the estimator held the
        # calibration, so fatci has used sigma_poly_m even with one (a bug kept here for
        # issue 18, whose estimates are bit-identical; passing cal fixes it)
        self.context = TrackContext(cfg, self.model, self.layout, None, self, self, self)
        self.tracks: list[Track] = [tracks.get(n)(self.context, cfg.settings.get(n)) for n in cfg.filters]
        takers: dict[type, list] = {}
        for track in self.tracks:
            for kind, handler in track.handlers().items():
                takers.setdefault(kind, []).append(handler)
        self._takers = takers
        self._motion, self._range, self._tdoa, self._fix, self._refused = (
            takers.get(k, []) for k in (Motion, Range, Tdoa, Fix, FixRefused))
        self._predicting = [track for track in self.tracks if track.predicts]
        self._own = {ImuSample: self._imu, Exchange: self._exchange, Restart: self._restart}
        self.need_sins = any(track.uses_strapdown for track in self.tracks)
        self.alignment = Alignment()
        self.aligned: AlignmentResult | None = None
        self.sins: Strapdown | None = None
        self.t: float | None = None  # filter time: the latest measurement's
        self.t_predicted: float | None = None  # the fusion tracks are predicted to here
        self.t_first: float | None = None  # the first measurement's: the start is known then
        self._t_imu_first: float | None = None
        self.t_imu: float | None = None
        self.t_aligned: float | None = None
        self._last_sample: tuple[tuple, tuple] | None = None  # (gyro, accel)
        self._k_out = 0  # next output instant: k * output_period_s
        self._next_out = 0.0  # its time
        self.fixes: list[Fix] = []  # the last two
        self.origin = tuple(cfg.start)  # where the strapdown starts when its alignment ends
        self._origin_since: float | None = None  # after an IMU restart: the fixes from then on,
        self._origin_fixes = (np.zeros(2), 0)  # summed and counted, give it (at rest: their mean)
        self._tilt_growth = (cfg.tilt_inflation * cfg.gravity * cfg.tilt_rate_sigma) ** 2
        self._accel_var = cfg.accel_sigma_m_s2**2
        self._range_scale = cal.scale if cal else cfg.range_scale
        self._range_bias = dict(cal.bias) if cal else {int(a): float(c) for a, c in cfg.range_bias_m.items()}
        sv, sa = cfg.stationary_sigma
        self._r_stationary = np.diag([sv**2, sv**2, sa**2, sa**2])
        self._at_rest = np.zeros(4)
        self._i2 = np.eye(2)
        self._gyro_limit = math.radians(cfg.gyro_range_dps)
        # opt-in: fn(t, filter, kind, dim, nis, accepted) per gated fusion update (the NIS
        # the report draws); None costs the tracks one attribute test
        self.on_innovation: Callable | None = None
        self.counts: Counter = Counter()
        self.input_rejections: Counter = Counter()
        self.emitted: Counter = Counter()

    # ---------------------------------------------------------------- inputs

    def feed(self, record) -> list[Estimate]:
        """One measurement record (host.measurements), in time order; the estimates of the
        output instants it passes."""
        own = self._own.get(type(record))
        return own(record) if own is not None else self._other(record)

    def _imu(self, rec: ImuSample) -> list[Estimate]:
        self.counts["imu"] += 1
        t_s = rec.t
        # plain floats: the strapdown's arithmetic is faster on them than on small arrays
        gyro = tuple(map(float, rec.gyro))
        accel = tuple(map(float, rec.accel))
        if not (math.isfinite(t_s) and all(map(math.isfinite, gyro)) and all(map(math.isfinite, accel))):
            self.input_rejections["imu_implausible"] += 1
            return []
        if rec.uptime_s is not None and self._t_imu_first is None:  # even on a stale sample
            self._t_imu_first = self._power_up(t_s, rec.uptime_s)
        if not rec.nd_ok:  # a repeated register read: the next sample covers the interval
            self.input_rejections["imu_stale"] += 1
            return []
        if self.t_imu is not None and t_s <= self.t_imu:
            self.input_rejections["imu_out_of_order"] += 1
            return []
        if max(map(abs, gyro)) >= self._gyro_limit:
            self.counts["imu_overrange"] += 1  # saturated, still the best reading there is
        out = self._begin(t_s)
        if self.t_imu is not None and t_s - self.t_imu > 1.5 * sins_format.PERIOD_S:  # a sample or more lost
            self._imu_gap(t_s)
        acceleration = self._sins_step(t_s, gyro, accel)
        if self._motion:
            if acceleration is None:
                m = Motion(t_s, "stationary", self._at_rest, self._r_stationary, STATIONARY)
            else:
                T = t_s - self.t_aligned
                R = (self._accel_var + self._tilt_growth * T * T) * self._i2
                m = Motion(t_s, "accel", np.array(acceleration[:2]), R, ACCELERATION)
            for take in self._motion:
                take(m)
        for take in self._takers.get(ImuSample, ()):
            take(rec)
        return self._end(t_s, out)

    def _exchange(self, rec: Exchange) -> list[Estimate]:
        """One exchange report; ``distance`` None when the exchange did not complete."""
        self.counts["exchanges"] += 1
        t_s, anchor, distance_m, status = rec.t, rec.anchor, rec.distance, rec.status
        if anchor not in self.layout:
            self.input_rejections["unknown_anchor"] += 1
            return []
        if not math.isfinite(t_s):
            self.input_rejections["range_implausible"] += 1
            return []
        out = self._begin(t_s)
        d = None
        if distance_m is None or not is_complete(status):
            self.input_rejections["outage" if status & STATUS_TIMEOUT else "incomplete"] += 1
        elif not (math.isfinite(distance_m) and 0.0 < distance_m <= self.cfg.max_range_m):
            self.input_rejections["range_implausible"] += 1
        else:
            d = (float(distance_m) - self._range_bias.get(anchor, 0.0)) / self._range_scale
            if self._range:
                m = Range(t_s, np.array([d]), np.array([[self.cfg.range_sigma_m**2]]),
                          Ranges(self.layout, (anchor,), (max(self.t - t_s, 0.0),)))
                for take in self._range:
                    take(m)
        for cycle in self.grouper.add(t_s, anchor, d):
            self._cycle(cycle)
        for take in self._takers.get(Exchange, ()):
            take(rec)
        return self._end(t_s, out)

    def _restart(self, rec: Restart) -> list[Estimate]:
        """``device`` (one of ``DEVICES``) restarted: its clock began a new epoch at t, so
        what the tracks hold need not be where the vehicle is; each track resets. An IMU
        restart also realigns the strapdown (the vehicle stands still after a power-up, like
        at the start) over the alignment_s since the power-up, ``uptime_s`` before t (its
        sample counter says; the host may see the board only after a while), or from t if
        that is more."""
        t_s, device = rec.t, rec.device
        if device not in DEVICES:
            raise ValueError(f"device {device!r}: use one of {', '.join(DEVICES)}")
        if not math.isfinite(t_s):
            self.input_rejections["restart_implausible"] += 1
            return []
        out = self._begin(t_s)
        self.grouper = CycleGrouper(len(self.layout.ids), self.cfg.cycle_s)  # no cycle spans it
        for track in self.tracks:
            track.restart(device, t_s)
        self.fixes = []
        if device == "imu":
            self.alignment = Alignment()
            self.sins = None
            self.t_aligned = self._last_sample = None
            self._t_imu_first = self._power_up(t_s, rec.uptime_s)
            self.origin, self._origin_since = tuple(self.cfg.start), t_s
            self._origin_fixes = (np.zeros(2), 0)
        return self._end(t_s, out)

    def _power_up(self, t_s: float, uptime_s: float) -> float | None:
        """When the board that has been up *uptime_s* at t_s powered up, if that is within
        the alignment (the vehicle stands still from then): the alignment counts from there.
        None: it is over (or the counter wrapped), the alignment counts from the next sample."""
        return t_s - uptime_s if 0.0 <= uptime_s < self.cfg.alignment_s else None

    def _imu_gap(self, t_s: float) -> None:
        """Samples were lost before t_s (a link fade, a pulled cable): up to ``imu_gap_s``
        the strapdown bridges the gap with this sample; beyond, its integration restarts at
        this sample (what happened in the gap is unknown) and every track that depends on
        it starts again from the next WSN fix (cause ``gap``)."""
        if t_s - self.t_imu <= self.cfg.imu_gap_s:
            self.counts["imu_gaps_bridged"] += 1
            return
        self.counts["imu_gaps_reinit"] += 1
        if self.sins is not None:
            self.t_imu = t_s  # the next step integrates from here, over nothing
        for track in self.tracks:
            track.gap(t_s)

    def _other(self, rec) -> list[Estimate]:
        """A record the estimator does not process: straight to the tracks that take it."""
        takers = self._takers.get(type(rec))
        if takers is None:
            raise TypeError(f"no track takes {type(rec).__name__} records; enable one that does")
        if not math.isfinite(rec.t):
            self.input_rejections[f"{type(rec).__name__}_implausible"] += 1
            return []
        out = self._begin(rec.t)
        for take in takers:
            take(rec)
        return self._end(rec.t, out)

    # ---------------------------------------------------------------- processing

    def _begin(self, t: float) -> list[Estimate]:
        """Start the tracks at the first measurement; emit the instants before t."""
        if self.t is None:
            self.t = self.t_predicted = self.t_first = t
            self._k_out = math.ceil(t / self.cfg.output_period_s)
            self._next_out = self._k_out * self.cfg.output_period_s
            for track in self.tracks:
                track.start(t)
        out = self._emit(t, through=False) if self._next_out < t else []
        self.t = max(self.t, t)
        return out

    def sync(self) -> None:
        """Predict the fusion tracks to the filter time. Lazily, before their next update:
        over measurements that update none of them (most exchanges), F(dt1 + dt2) =
        F(dt2) F(dt1) and the Q likewise make one predict the same as several."""
        dt = self.t - self.t_predicted
        for track in self._predicting:
            track.predict(dt)
        self.t_predicted = self.t

    def _end(self, t: float, out: list[Estimate]) -> list[Estimate]:
        """out and the estimates of the output instants up to t."""
        return out + self._emit(t, through=True) if self._next_out <= t else out

    def _sins_step(self, t: float, gyro: tuple, accel: tuple) -> tuple | None:
        """Advance alignment or strapdown; the nav-frame horizontal acceleration once aligned."""
        if self._t_imu_first is None:
            self._t_imu_first = t
        try:
            if self.sins is None:
                if not self.need_sins or t - self._t_imu_first < self.cfg.alignment_s \
                        or self._last_sample is None:
                    self.alignment.add(gyro, accel)
                    self._last_sample = (gyro, accel)
                    return None
                self._start_strapdown()
            return self.sins.step(t - self.t_imu, gyro, accel)[:2]
        finally:
            self.t_imu = t

    def _start_strapdown(self) -> None:
        c = self.cfg
        self.aligned = a = self.alignment.result(c.heading0_rad, math.radians(c.latitude_deg), c.x_azimuth_deg)
        self.sins = Strapdown(position=self.origin, q=a.q, gyro_bias=a.gyro_bias, latitude_deg=c.latitude_deg,
                              gravity=c.gravity, altitude_m=c.altitude_m, x_azimuth_deg=c.x_azimuth_deg)
        self.sins.step(0.0, *self._last_sample)  # the interval to the next sample starts here
        self.t_aligned = self.t_imu

    def _cycle(self, cycle) -> None:
        """A closed TDMA cycle: the WSN fix (re-initialisations of the tracks waiting for
        one, the SINS origin after a restart, then the tracks that take fixes), and the
        TDOA product."""
        # the previous fix tells TDOA mirror positions apart (three anchors: both fit exactly)
        near = self.fixes[-1].p if self.fixes else None
        fix = self.solver.fix(cycle.t, cycle.valid_anchors, cycle.distances, near)
        if isinstance(fix, str):
            refused = FixRefused(cycle.t, fix)
            for take in self._refused:
                take(refused)
            fix = None
        else:
            # two fixes with one time would give no velocity: keep the newer
            older = [f for f in self.fixes[-1:] if f.t < fix.t]
            self.fixes = [*older, fix]
            if self.sins is None and self._origin_since is not None and fix.t >= self._origin_since:
                total, n = self._origin_fixes[0] + fix.p, self._origin_fixes[1] + 1
                self._origin_fixes, self.origin = (total, n), tuple((total / n).tolist())
            for track in self.tracks:
                track.offer_fix(fix)
            for take in self._fix:
                take(fix)
        if self._tdoa:
            m = self._tdoa_product(cycle, fix)
            for take in self._tdoa:
                take(m)

    def _tdoa_product(self, cycle, fix: Fix | None) -> Tdoa:
        """Range differences to the reference anchor (000 eqs. 12-13), R = sigma^2 (I + 11^T)."""
        r = dict(zip(cycle.valid_anchors, cycle.distances))
        t_of = dict(zip(cycle.valid_anchors, cycle.valid_times))
        ref = self.cfg.reference_anchor if self.cfg.reference_anchor in r else min(r, default=None)
        # |r_i - r_ref| cannot exceed the anchors' separation (triangle inequality), give or
        # take 4 sigma of the difference's noise (it is tight on the line through the two)
        slack = 4.0 * math.sqrt(2.0) * self.cfg.range_sigma_m
        others = []
        implausible = 0
        for a in r:
            if a != ref and abs(r[a] - r[ref]) <= self.layout.baseline(a, ref) + slack:
                others.append(a)
            elif a != ref:
                implausible += 1
        if len(others) < 2:
            return Tdoa(cycle.t, implausible, fix=fix)
        keep = [ref, *others]
        z = np.array([r[a] - r[ref] for a in others])
        meas = Ranges(self.layout, keep, [max(self.t - t_of[a], 0.0) for a in keep], reference=ref)
        R = tdoa_covariance(self.cfg.range_sigma_m, len(others))
        return Tdoa(cycle.t, implausible, z, R, meas, fix)

    # ---------------------------------------------------------------- output

    def _emit(self, t: float, through: bool) -> list[Estimate]:
        """The estimates of the output instants before t (``through``: up to t inclusive)."""
        out = []
        while (b := self._next_out) < t or (through and b == t):
            yaw = self.sins.yaw if self.sins is not None else self.cfg.heading0_rad
            for track in self.tracks:
                e = track.estimate(b, yaw)
                if e is not None:
                    out.append(e if e.vehicle == self.cfg.vehicle else
                               replace(e, vehicle=self.cfg.vehicle))
                    self.emitted[track.name] += 1
            self._k_out += 1
            self._next_out = self._k_out * self.cfg.output_period_s
        return out

    def stale(self, b: float, t_aided: float | None) -> bool:
        """Whether an estimate at b, last aided at t_aided (None: never, only the configured
        start at the first measurement), is extrapolated."""
        return b - (self.t_first if t_aided is None else t_aided) > self.cfg.extrapolated_after_s

    # ---------------------------------------------------------------- status

    @property
    def reinit_count(self) -> int:
        """Every re-initialisation so far: one int to watch for a new one."""
        return sum(sum(track.reinits.values()) for track in self.tracks)

    def imu_gaps(self) -> dict:
        """IMU gaps so far: ``bridged`` (the state kept) and ``reinit`` (the tracks restarted)."""
        return {"bridged": self.counts["imu_gaps_bridged"], "reinit": self.counts["imu_gaps_reinit"]}

    def stats(self) -> dict:
        """Counts: inputs, input rejections, updates and rejections per aided track by
        kind/reason, estimates emitted, re-initialisations, and the alignment result."""
        a = self.aligned
        return {
            "imu_samples": self.counts["imu"],
            "imu_overrange": self.counts["imu_overrange"],
            "imu_gaps": self.imu_gaps(),
            "exchanges": self.counts["exchanges"],
            "input_rejections": dict(sorted(self.input_rejections.items())),
            "updates": {t.name: dict(sorted(t.updates.items())) for t in self.tracks if t.aided},
            "rejections": {t.name: dict(sorted(t.rejections.items())) for t in self.tracks if t.aided},
            "estimates": {t.name: self.emitted[t.name] for t in self.tracks},
            "reinit": {t.name: dict(sorted(t.reinits.items())) for t in self.tracks if t.reinits},
            "reinit_pending": [t.name for t in self.tracks if t.pending],
            "alignment": None if a is None else {
                "samples": a.samples, "roll_rad": a.roll, "pitch_rad": a.pitch, "yaw_rad": a.yaw,
                "gyro_bias_rad_s": [float(v) for v in a.gyro_bias],
                "specific_force_m_s2": a.specific_force},
        }
