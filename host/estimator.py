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
* host.timebase.FilterTime: the filter time (the latest measurement's), the output
  instants, and when an estimate is extrapolated;
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

A track that fails. A track whose step raises an arithmetic error (a math domain error, an
overflow, a singular matrix: ValueError, ArithmeticError) or gives an estimate that is not
finite is off from then (cause ``error``, counted in ``stats()["reinit"]``, its last error's
line in ``stats()["track_errors"]``) and starts again at the next fix, as after a restart;
the other tracks, and the host, run on. A bug that raises anything else still stops the run.
"""
from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import replace

from . import tracks
from .filters import ConstantAcceleration
from .inertial import Inertial
from .measurements import (AnchorExchange, Exchange, Fix, FixRefused, ImuSample, MagSample, Motion, Range, Restart,
                           Tdoa)
from .ranging import Ranging
from .settings import EstimatorConfig
from .timebase import FilterTime
from .tracks.base import Estimate, Track, TrackContext
from .wsn import AnchorLayout

__all__ = ["DEVICES", "Estimate", "Estimator"]

DEVICES = ("imu", "anchors")  # what can restart (a Restart record)
#: what a track's step may raise on numbers gone bad (module doc, "A track that fails")
FAILURES = (ArithmeticError, ValueError)
#: records a lab sends whether or not an enabled track uses them (an optional sensor)
IGNORED_UNTAKEN = (MagSample, AnchorExchange)


class Estimator:
    """The fusion core (module docstring): records in, estimates out; dispatch, restarts,
    output instants and stats here, the rest in its parts ``inertial``, ``ranging``,
    ``time`` and the tracks' ``context``."""

    def __init__(self, cfg: EstimatorConfig):
        self.cfg = cfg
        self.layout = AnchorLayout(cfg.anchors, cfg.tag_height)
        self.calibration = cfg.calibration
        classes = [tracks.get(n) for n in cfg.filters]
        self.inertial = Inertial(cfg, need_sins=any(cls.uses_strapdown for cls in classes))
        self.ranging = Ranging(cfg, self.layout)
        self.time = FilterTime(cfg.output_period_s, cfg.extrapolated_after_s)
        self.context = TrackContext(cfg, ConstantAcceleration(cfg.jerk_psd), self.layout,
                                    self.calibration,
                                    time=self.time, inertial=self.inertial, ranging=self.ranging,
                                    estimator=self)
        self.tracks: list[Track] = [cls(self.context, cfg.settings.get(n))
                                    for n, cls in zip(cfg.filters, classes)]
        # record or product type -> its takers: (track, its handler)
        self._takers: dict[type, list[tuple[Track, Callable]]] = {}
        for track in self.tracks:
            for kind, handler in track.handlers().items():
                self._takers.setdefault(kind, []).append((track, handler))
        self.track_errors: dict[str, str] = {}  # track -> the line of its last failure
        # record type -> (its part's check, its processing); other types: straight to takers
        self._own = {ImuSample: (self.inertial.accept, self._imu),
                     Exchange: (self.ranging.accept, self._exchange),
                     Restart: (self._restartable, self._restart)}
        # opt-in: fn(t, filter, kind, dim, nis, accepted) per gated fusion update (the NIS
        # the report draws); None costs the tracks one attribute test
        self.on_innovation: Callable | None = None
        self.input_rejections: Counter = Counter()  # restarts, other records: the parts count their own
        self.emitted: Counter = Counter()

    def takes(self) -> frozenset:
        """The record and product types some track takes."""
        return frozenset(self._takers)

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
        for track, take in self._takers.get(kind, ()):
            try:
                take(item)
            except FAILURES as e:
                self._failed(track, e)

    def _failed(self, track: Track, error: BaseException) -> None:
        """*track* failed (module doc): off until the next fix."""
        self.track_errors[track.name] = f"{type(error).__name__}: {error}"
        track.discontinuity("error", self.time.t)

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
                try:
                    track.offer_fix(fix)
                except FAILURES as e:
                    self._failed(track, e)
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
        """A record the estimator does not process goes straight to the tracks that take it;
        a sensor's that no enabled track takes (IGNORED_UNTAKEN) is counted and dropped."""
        if type(rec) not in self._takers:
            if type(rec) in IGNORED_UNTAKEN:
                self.input_rejections[f"{type(rec).__name__}_untaken"] += 1
                return False
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
            yaw = sins.yaw if sins is not None else self.cfg.heading_rad
            for track in self.tracks:
                try:
                    e = track.estimate(b, yaw)
                    if e is not None and not math.isfinite(e.x + e.y + e.vx + e.vy):
                        raise FloatingPointError(f"estimate ({e.x}, {e.y}) m, ({e.vx}, {e.vy}) m/s")
                except FAILURES as error:
                    self._failed(track, error)
                    continue
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
            **({"track_errors": dict(sorted(self.track_errors.items()))} if self.track_errors else {}),
            "alignment": self.inertial.stats(),
        }
