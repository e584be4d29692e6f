"""What the fusion tracks (kf, ekf, ukf) share: a filter on the constant-acceleration
state x = [x, y, vx, vy, ax, ay] (host.filters), gated updates, re-initialisation.

Time. A fusion track predicts lazily: before an update it predicts its state from the time
it was predicted to (``t_predicted``) to the filter time, so one predict spans the records
that updated nothing of it (F(dt1 + dt2) = F(dt2) F(dt1) and the Q likewise: one predict is
several). Each track keeps its own time, so its numbers do not depend on which other tracks
run beside it (the batch engine, host.batch, runs some of them apart). A measurement older
than the filter time is applied with its lag through the motion model if the lag is at most
``max_lag_s``, else rejected as ``late``.

Gating (docs/filters.md). An update whose innovation fails the chi-square gate
(``gate_probability``) is rejected; every acceleration update gated out for
``gate_reopen_s`` is applied ungated (the track's acceleration is off), every position
update gated out that long makes the track start again (a discontinuity, cause
``gated``) from the next WSN fix newer than it: the fix's position and covariance, at rest
with ``reinit_sigma`` on velocity and acceleration. A device restart does the same (cause
``restart``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import key, one_of
from navtwin.host.measurements import Motion, Range, Tdoa
from navtwin.host.measurements import Fix
from navtwin.host.wsn import chi2_gate

from .base import Track, estimate

POSITION_KINDS = frozenset(("fix", "tdoa", "range"))  # the updates that aid a track's position


class FusionTrack(Track):
    uses_strapdown = True

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.filter = None
        self.t_predicted: float | None = None  # the filter is predicted to here (<= ctx.t)
        self._aided: float | None = None  # time of its last position update
        self._gated_since: dict[str, float] = {}  # kind -> first rejection of a run of them

    def make_filter(self, x0: np.ndarray, P0: np.ndarray):
        """The track's filter at (x0, P0) on the estimator's motion model."""
        raise NotImplementedError

    def handlers(self) -> dict:
        return {Motion: self.motion}

    # -- life -------------------------------------------------------------------------------
    def _new_filter(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.filter = self.make_filter(x0, P0)
        self._gated_since = {}  # a new track has no run of rejections

    def _p0(self) -> np.ndarray:
        sp, sv, sa = self.ctx.cfg.p0_sigma
        return np.diag([sp**2, sp**2, sv**2, sv**2, sa**2, sa**2])

    def start(self, t: float) -> None:
        self._new_filter(np.array([*self.ctx.cfg.start, 0.0, 0.0, 0.0, 0.0]), self._p0())
        self.t_predicted = t

    def sync(self) -> None:
        """Predict the filter to the filter time (module doc, "Time")."""
        t = self.ctx.t
        if self.t_predicted < t:
            try:
                self.filter.predict(t - self.t_predicted)
            except np.linalg.LinAlgError:
                self._reset()
            self.t_predicted = t

    def _reset(self) -> None:
        """A covariance lost positive definiteness (never seen; rounding can do it): start
        again at the latest WSN fix, else the SINS."""
        ctx = self.ctx
        self.rejections["numerical_reset"] += 1
        p = ctx.fixes[-1].p if ctx.fixes else ctx.sins.p[:2] if ctx.sins else ctx.cfg.start
        v = ctx.sins.v[:2] if ctx.sins else (0.0, 0.0)
        self._new_filter(np.array([*p, *v, 0.0, 0.0]), self._p0())

    def restart(self, device: str, t: float) -> None:
        self.discontinuity("restart", t)

    def gap(self, t: float) -> None:
        self.discontinuity("gap", t)  # its motion input stopped: the state is not the vehicle's

    def reinit_at(self, fix: Fix) -> bool:
        """Start again at ``fix``: its position and covariance, at rest but with
        ``reinit_sigma`` on velocity and acceleration (they are unknown). The track takes no
        other update from this fix's cycle (the same ranges)."""
        sv, sa = self.ctx.cfg.reinit_sigma
        P0 = np.diag([0.0, 0.0, sv**2, sv**2, sa**2, sa**2])
        P0[:2, :2] = fix.cov
        self._new_filter(np.array([*fix.p, 0.0, 0.0, 0.0, 0.0]), P0)
        self._aided = fix.t
        return True

    # -- updates ----------------------------------------------------------------------------
    def motion(self, m: Motion) -> None:
        self._update(m.kind, m.z, m.R, m.meas, m.t)

    def _update(self, kind: str, z, R, meas, t: float) -> None:
        """One gated update; counts the outcome by kind or reason."""
        ctx = self.ctx
        cfg = ctx.cfg
        if ctx.t - t > cfg.max_lag_s:
            self.rejections["late"] += 1
            return
        self.sync()
        f = self.filter
        try:
            inn = f.update(z, R, meas, chi2_gate(meas.dim, cfg.gate_probability))
            if ctx.on_innovation is not None:
                ctx.on_innovation(t, self.name, kind, meas.dim, inn.nis, inn.accepted)
            if not inn.accepted:
                gated_for = t - self._gated_since.setdefault(kind, t)
                if gated_for > cfg.gate_reopen_s and kind not in POSITION_KINDS:
                    # the acceleration gated out for so long: the track's acceleration is off
                    self.rejections["gate_reopened"] += 1
                    f.update(z, R, meas)
                else:
                    self.rejections["gate"] += 1
                    if gated_for > cfg.gate_reopen_s:
                        # every position update gated out for so long: the track, not the WSN, is off
                        self.discontinuity("gated", t)
                    return
        except np.linalg.LinAlgError:
            self._reset()
            return
        if self._gated_since:
            self._gated_since.pop(kind, None)
        if kind in POSITION_KINDS:
            self._aided = t
        self.updates[kind] += 1

    # -- output -----------------------------------------------------------------------------
    def estimate(self, b: float, yaw: float):
        ctx = self.ctx
        x, P = ctx.model.propagate(self.filter.x, self.filter.P, b - self.t_predicted)
        stale = self.pending or ctx.stale(b, self._aided)  # waiting: off
        return estimate(b, self.name, x[:2], x[2:4], yaw, P[:4, :4], stale)


@dataclass(frozen=True)
class TightSettings:
    """A tightly coupled track's own settings (``[filters.ekf]``; ``[filters.ukf]`` extends
    them)."""

    tight: str = key("tdoa", "", "range measurement: per cycle (tdoa) or each range (toa)",
                     one_of("toa", "tdoa"))


class TightTrack(FusionTrack):
    """Tightly coupled: measures the ranges themselves, each cycle's differences to the
    reference anchor (its ``tight = "tdoa"``) or each range at its own time (``"toa"``)."""

    Settings = TightSettings

    def handlers(self) -> dict:
        if self.settings.tight == "toa":  # the estimator makes Range and Tdoa products for their takers
            return {**super().handlers(), Range: self.range}
        return {**super().handlers(), Tdoa: self.tdoa}

    def range(self, m: Range) -> None:
        self._update("range", m.z, m.R, m.meas, m.t)

    def tdoa(self, m: Tdoa) -> None:
        if m.fix is not None and m.fix is self.reinit_fix:
            return
        self.rejections["implausible"] += m.implausible
        if m.meas is None:
            self.rejections["too_few"] += 1
            return
        self._update("tdoa", m.z, m.R, m.meas, m.t)
