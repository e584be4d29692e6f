"""What the fusion tracks' twins (kf, ekf, ukf) share, as host.tracks.fusion's FusionTrack and
TightTrack are shared per seed: the constant-acceleration state of each seed (x (n, 6),
P (n, 6, 6)), predicted lazily to the filter time from its own ``t_predicted``, and the
gated update with its runs of rejections, for the rows of the seeds a product reaches.

A twin names its filter's correction (:meth:`BatchFusionTrack.correct`: the Joseph update
linearised at the prior, the KF's and the EKF's; the UKF's its own) and the products it
takes; the measurements are host.batch.model's, each seed's rows its own.

A rejection, an acceleration update re-opened, and a position kind gated out for
``gate_reopen_s`` are here: the last is the track's discontinuity (``gated``), which waits,
taking its updates and reporting stale estimates, for the next WSN fix no older than it
and starts again there (FusionTrack.reinit_at; the fix's cycle's other updates skipped):
every seed's ekf and ukf do it on rssi-centroid, so it is the common path. A numerical
failure (a singular innovation covariance, a covariance not positive definite: the
per-seed track's reset) hands the seeds back to be run per seed (host.batch.tracks.base).
"""
from __future__ import annotations

import numpy as np

from navtwin.host.measurements import Fix, Motion, Range, Tdoa
from navtwin.host.tracks.fusion import POSITION_KINDS, TightSettings
from navtwin.host.wsn import chi2_gate

from ..innovation import joseph_correct
from ..kf import propagate
from ..model import BatchLinear, BatchRanges
from ..seeds import take, whole
from .base import BatchTrack, Columns


class BatchFusionTrack(BatchTrack):
    uses_strapdown = ca_state = True
    # x (n, 6), P (n, 6, 6) and FusionTrack.t_predicted (n,): rows of the estimator's stack,
    # given by it (host.batch.tracks.base)
    x: np.ndarray
    P: np.ndarray
    t_predicted: np.ndarray

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        n = ctx.n
        self._I = np.eye(6)
        self.aided = np.full(n, np.nan)  # time of the last position update; NaN: none
        self._gated_since: dict[str, np.ndarray] = {}  # kind -> first rejection of a run; NaN: none
        self.reinit_since = np.full(n, np.nan)  # Track.reinit_since; NaN: running
        self.reinit_fix = np.zeros(n, np.int64)  # Track.reinit_fix: the number of the fix it
        # last started again at (host.batch.ranging; 0: none)

    def handlers(self) -> dict:
        return {Motion: self.motion, Fix: self.offer_fix}

    def correct(self, x, P, z, R, meas, gate):
        """The filter's update of the rows x (k, 6), P (k, 6, 6) with z (k, m) through *meas*
        (host.batch.model): (x, P, BatchInnovation). The Joseph form linearised at the prior
        (host.filters.ekf; for a linear *meas*, host.filters.kf)."""
        hx, H = meas.linearize(x)
        return joseph_correct(x, P, self._I, z - hx, H, R, gate)

    def start(self, idx, t) -> None:
        sp, sv, sa = self.ctx.cfg.p0_sigma
        self.x[idx] = [*self.ctx.cfg.start, 0.0, 0.0, 0.0, 0.0]
        self.P[idx] = np.diag([sp**2, sp**2, sv**2, sv**2, sa**2, sa**2])
        self.aided[idx] = np.nan
        self.t_predicted[idx] = t

    def offer_fix(self, idx, f) -> np.ndarray:
        """Track.offer_fix: the seeds waiting since a discontinuity no later than the fix
        start again at it (FusionTrack.reinit_at: its position and covariance, at rest with
        ``reinit_sigma`` on velocity and acceleration, no run of rejections); which did."""
        at = f.t >= self.reinit_since[idx]  # NaN: not waiting
        if at.any():
            rows = idx[at]
            sv, sa = self.ctx.cfg.reinit_sigma
            P0 = np.zeros((len(rows), 6, 6))
            P0[:, 2, 2] = P0[:, 3, 3] = sv**2
            P0[:, 4, 4] = P0[:, 5, 5] = sa**2
            P0[:, :2, :2] = f.cov[at]
            self.x[rows] = 0.0
            self.x[rows, :2] = f.p[at]
            self.P[rows] = P0
            self.aided[rows] = f.t[at]
            for since in self._gated_since.values():
                since[rows] = np.nan
            self.reinit_since[rows] = np.nan
            self.reinit_fix[rows] = f.number[at]
        return at

    def sync(self, idx) -> None:
        """FusionTrack.sync: the seeds *idx* predicted to their filter time."""
        t = self.ctx.t[idx]
        behind = self.t_predicted[idx] < t
        if behind.any():
            b = idx[behind]
            self.x[b], self.P[b] = self._propagate(b, t[behind] - self.t_predicted[b])
            self.t_predicted[b] = t[behind]

    def _propagate(self, idx, dt):
        """ConstantAcceleration.propagate of the seeds *idx*, each over its dt (the UKF's
        predict too: its transform through the linear F is this, in closed form)."""
        return propagate(self.x[idx], self.P[idx], *self.ctx.model.many(dt))

    def motion(self, idx, m) -> None:
        self._update(idx, m.z, m.R, BatchLinear(m.meas.H), m.t, m.kind)

    def _update(self, idx, z, R, meas, t, kind: str) -> None:
        """FusionTrack._update: the late ones left out, the rest synced and updated, the
        gated-out ones' runs of rejections followed (module doc)."""
        ctx = self.ctx
        on = ctx.t[idx] - t <= ctx.cfg.max_lag_s
        if not on.all():
            idx, z, t, R, meas = idx[on], z[on], t[on], take(R, 2, on), meas.take(on)
        if not idx.size:
            return
        self.sync(idx)
        at = whole(idx, ctx.n)
        try:
            x, P, inn = self.correct(self.x[at], self.P[at], z, R, meas,
                                     chi2_gate(meas.dim, ctx.cfg.gate_probability))
        except np.linalg.LinAlgError:
            ctx.eject(idx, f"{self.name}: numerical reset")
            return
        self.x[at], self.P[at] = x, P
        since = self._gated_since.get(kind)
        if since is None:
            since = self._gated_since[kind] = np.full(ctx.n, np.nan)
        out = ~inn.accepted
        if out.any():  # the run of rejections of this kind goes on, or starts now
            r = idx[out]
            since[r] = np.where(np.isnan(since[r]), t[out], since[r])
            long = t[out] - since[r] > ctx.cfg.gate_reopen_s
            if kind in POSITION_KINDS:  # the track, not the WSN, is off: it starts again
                self.reinit_since[r[long]] = t[out][long]  # at the next fix (Track.discontinuity)
            elif long.any():  # the acceleration is off: its update applies ungated
                k = np.flatnonzero(out)[long]
                rows = idx[k]
                try:
                    self.x[rows], self.P[rows], _ = self.correct(
                        self.x[rows], self.P[rows], z[k], take(R, 2, k), meas.take(k), None)
                except np.linalg.LinAlgError:
                    ctx.eject(rows, f"{self.name}: numerical reset")
                out[k] = False
        taken = idx[~out]
        since[taken] = np.nan
        if kind in POSITION_KINDS:
            self.aided[taken] = t[~out]

    def estimate(self, idx, b) -> Columns:
        ctx = self.ctx
        x, P = self._propagate(idx, b - self.t_predicted[idx])
        stale = ~np.isnan(self.reinit_since[idx]) | ctx.stale(idx, b, self.aided[idx])
        return Columns(np.ones(len(idx), bool), x[:, :2], x[:, 2:4], P[:, :4, :4], stale, True)


class BatchTightTrack(BatchFusionTrack):
    """host.tracks.fusion.TightTrack: the ranges themselves, each cycle's differences to the
    reference anchor (``tight = "tdoa"``) or each range at its own time (``"toa"``)."""

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, TightSettings() if settings is None else settings)

    def handlers(self) -> dict:
        if self.settings.tight == "toa":
            return {**super().handlers(), Range: self.range}
        return {**super().handlers(), Tdoa: self.tdoa}

    def range(self, idx, m) -> None:
        """Each seed's range (host.batch.estimator.RangeBatch), R = range_sigma_m^2."""
        R = np.array([[self.ctx.cfg.range_sigma_m**2]])
        meas = BatchRanges.of(self.ctx.layout, m.row[:, None], m.lag[:, None])
        self._update(idx, m.z[:, None], R, meas, m.t, "range")

    def tdoa(self, idx, b) -> None:
        """The Tdoa of a cycle of the seeds *idx*, all with the same anchors, the reference
        first (host.batch.ranging.TdoaBatch): one stacked update, but for the seeds that
        started again at the cycle's fix."""
        on = (b.fix == 0) | (b.fix != self.reinit_fix[idx])
        if not on.all():
            idx, b = idx[on], b.take(on)
        if idx.size:
            self._update(idx, b.z, b.R, BatchRanges.of(self.ctx.layout, b.rows, b.lags, 0), b.t, "tdoa")
