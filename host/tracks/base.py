"""The interface of a fusion track: one output stream of estimates (docs/filters.md).

A track is a class with a ``name`` (its ``filter`` in the output and its section
``[filters.<name>]`` in the host config), a ``Settings`` frozen dataclass declared with
:func:`navtwin.common.schema.key` (units, docs, checks: the config reads and documents it), and:

* :meth:`handlers`: which records (host.measurements: ImuSample, Exchange, ...) and shared
  products (host.measurements: Motion, Range, Tdoa, Fix, FixRefused) it takes, each with the
  method that takes it; the estimator calls these in time order;
* :meth:`estimate`: what it emits at an output instant (an Estimate, or None before it has
  one), with ``extrapolated`` set from its last aiding;
* :meth:`restart`: its reset when a device restarts, :meth:`gap` after a gap in the IMU
  stream too long to bridge; a track that then starts again from the next WSN fix calls
  :meth:`discontinuity`, and the estimator offers it each new fix (:meth:`offer_fix`,
  which calls its :meth:`reinit_at`);
* its stats: ``updates`` and ``rejections`` (Counters by kind or reason) and ``reinits``.

A track sees the estimator only through its :class:`TrackContext` (``self.ctx``): the time
base, the shared settings and models, the strapdown and the WSN fixes, read-only. Nothing
else of the estimator is reachable from it: an undeclared member is an AttributeError.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np


class TrackContext:
    """What a track may use of the estimator (``self.ctx``), and nothing more.

    Built by the estimator from its parts: the settings and models (fixed for the run), the
    time base (host.timebase.FilterTime: ``t``, ``stale``), the
    inertial part (host.inertial.Inertial: ``sins``, ``origin``, ``t_imu``, ``t_aligned``),
    the ranging part (host.ranging.Ranging: ``fixes``) and the estimator's
    ``on_innovation``. The dynamic members are read through at each access, so a track sees
    the current value; a track changes none of them.
    """

    __slots__ = {
        "cfg": "The estimator's settings (host.settings.EstimatorConfig: the host config's "
               "[filters] keys, the site, the anchors, the start).",
        "model": "The shared constant-acceleration motion model (host.filters."
                 "ConstantAcceleration, jerk_psd) that the fusion tracks predict on.",
        "layout": "The anchors (host.wsn.AnchorLayout: ids, positions, the tag height).",
        "calibration": "001's range calibration (host.calibration.Calibration: f, c_i, "
                       "sigma(d)), or None without one.",
        "stale": "stale(b, t_aided) -> bool: whether an estimate at b, last aided at t_aided "
                 "(None: never, only the configured start), is extrapolated "
                 "(extrapolated_after_s).",
        "_time": "the time base", "_inertial": "the strapdown's owner",
        "_ranging": "the fixes' owner", "_estimator": "on_innovation's owner",
    }

    def __init__(self, cfg, model, layout, calibration, *, time, inertial, ranging, estimator) -> None:
        self.cfg, self.model, self.layout, self.calibration = cfg, model, layout, calibration
        self.stale = time.stale
        self._time, self._inertial, self._ranging, self._estimator = time, inertial, ranging, estimator

    @property
    def t(self) -> float | None:
        """The filter time (s): the latest measurement's; None before the first."""
        return self._time.t

    @property
    def on_innovation(self) -> Callable | None:
        """fn(t, filter, kind, dim, nis, accepted), to call after each gated update (the
        NIS the report draws), or None (the usual: test it before building the arguments)."""
        return self._estimator.on_innovation

    @property
    def sins(self):
        """The estimator's strapdown (host.sins.Strapdown: p, v, yaw, f_n, copy()), None
        until the alignment ends (and again from an IMU restart until it realigns)."""
        return self._inertial.sins

    @property
    def origin(self) -> tuple[float, float]:
        """Where the strapdown starts when its alignment ends (m): the configured start, or
        after an IMU restart the mean of the fixes since."""
        return self._inertial.origin

    @property
    def t_imu(self) -> float | None:
        """The time (s) of the latest IMU sample the strapdown took."""
        return self._inertial.t_imu

    @property
    def t_aligned(self) -> float | None:
        """The time (s) the alignment ended, None while it runs."""
        return self._inertial.t_aligned

    @property
    def fixes(self) -> list:
        """The last two WSN fixes (host.measurements.Fix), oldest first, of distinct times; fewer
        at the start and after a restart."""
        return self._ranging.fixes


@dataclass(frozen=True, slots=True)
class Estimate:
    """One track's estimate at an output instant (docs/filters.md, host.output)."""

    t: float
    filter: str
    x: float
    y: float
    vx: float
    vy: float
    yaw: float | None
    cov: list[float]  # 4x4 covariance of (x, y, vx, vy), row-major
    extrapolated: bool = False  # the track had no aiding for extrapolated_after_s before t
    vehicle: int = 1  # the lab's vehicle (host config, numbered from 1); the estimator sets it


def estimate(t, name, p, v, yaw, cov4, extrapolated: bool) -> Estimate:
    """p, v: sequences of 2; cov4: a 4x4 array, or its 16 floats row-major."""
    (x, y), (vx, vy) = np.asarray(p, float).tolist(), np.asarray(v, float).tolist()
    cov = cov4 if isinstance(cov4, list) else np.ravel(cov4).tolist()
    return Estimate(float(t), name, x, y, vx, vy, None if yaw is None else float(yaw), cov,
                    bool(extrapolated))


@dataclass(frozen=True)
class NoSettings:
    """A track without settings of its own."""


class Track:
    name: ClassVar[str]
    Settings: ClassVar[type] = NoSettings
    #: Uses the strapdown (so the estimator runs it after the alignment) and its yaw.
    uses_strapdown: ClassVar[bool] = False
    #: Takes updates, so its stats report updates and rejections.
    aided: ClassVar[bool] = True
    #: (module, extra) pairs of optional packages the track imports when it starts: checked
    #: when it is named (host.config.parse_filters), so a run without them never begins.
    requires: ClassVar[tuple[tuple[str, str], ...]] = ()

    def __init__(self, ctx: TrackContext, settings=None) -> None:
        self.ctx = ctx
        self.settings = self.Settings() if settings is None else settings
        self.updates: Counter = Counter()
        self.rejections: Counter = Counter()
        self.reinits: Counter = Counter()
        #: The time of a discontinuity: the track starts again at the first WSN fix no
        #: older than it (:meth:`offer_fix`); None while it runs.
        self.reinit_since: float | None = None
        #: The fix it last started again at: its cycle's other updates are the same ranges.
        self.reinit_fix = None

    def handlers(self) -> dict[type, Callable]:
        """Record or product type -> the method that takes it."""
        return {}

    def start(self, t: float) -> None:
        """The first measurement of the run, at t."""

    def restart(self, device: str, t: float) -> None:
        """``device`` restarted at t: what the track holds need not be where the vehicle is."""

    def gap(self, t: float) -> None:
        """The IMU stream had a gap longer than ``imu_gap_s`` before t, which the strapdown
        did not bridge (host.inertial)."""

    def discontinuity(self, cause: str, t: float) -> None:
        """Off for ``cause`` at t: start again from the next WSN fix no older than t
        (counted once per discontinuity, however many causes it has)."""
        if self.reinit_since is None:
            self.count_reinit(cause)
        self.reinit_since = t

    def offer_fix(self, fix) -> None:
        """A new WSN fix (host.measurements.Fix), before the tracks that take fixes see it: a track
        waiting since a discontinuity no later than the fix starts again at it."""
        since = self.reinit_since
        if since is not None and fix.t >= since and self.reinit_at(fix):
            self.reinit_since, self.reinit_fix = None, fix

    def reinit_at(self, fix) -> bool:
        """Start again at *fix* (a host.measurements.Fix); False: not yet, keep waiting. A track
        whose estimates come from what it shares (the fixes, the estimator's strapdown: wsn,
        sins, the centroids) has nothing of its own to start again: it runs on at once."""
        return True

    @property
    def pending(self) -> bool:
        """Waiting to re-initialise."""
        return self.reinit_since is not None

    def estimate(self, b: float, yaw: float) -> Estimate | None:
        raise NotImplementedError

    def unstarted(self, b: float, yaw: float) -> Estimate:
        """The estimate of a track on its own strapdown before it has one: at its start, at
        rest, with P0's sigmas."""
        ctx = self.ctx
        sp, sv, _ = ctx.cfg.p0_sigma
        cov = np.diag([sp**2, sp**2, sv**2, sv**2])
        return estimate(b, self.name, ctx.origin, (0.0, 0.0), yaw, cov, ctx.stale(b, None))

    def count_reinit(self, cause: str) -> None:
        self.reinits[cause] += 1


class OwnStrapdown:
    """A track that corrects a strapdown of its own (a mixin of Track): ``nav``, a copy of the
    estimator's taken at the IMU sample that ends the alignment, then stepped with every
    sample the estimator accepts (the same samples, the same integration); ``t_nav`` is its
    last sample's time. A subclass gives :meth:`started` and :meth:`stepped`."""

    nav = None
    t_nav: float | None = None

    def started(self, t: float) -> None:
        """The copy was taken at t."""

    def stepped(self, t: float, dt: float) -> None:
        """The strapdown was stepped dt to t."""

    def imu(self, rec) -> None:
        sins = self.ctx.sins
        if sins is None:
            return
        if self.nav is None:  # the alignment ended with this sample: start from its strapdown
            self.nav = sins.copy()
            self.t_nav = rec.t
            self.started(rec.t)
            self.reinit_since = None
            return
        dt = rec.t - self.t_nav
        self.nav.step(dt, tuple(map(float, rec.gyro)), tuple(map(float, rec.accel)))
        self.t_nav = rec.t
        self.stepped(rec.t, dt)
