"""``kf``'s twin (host.tracks.kf and its base host.tracks.fusion.FusionTrack): the linear KF
on the constant-acceleration state, predicted at each update to the filter time, measuring
the Motion product and each WSN fix with its lag, for the rows of many seeds (the products
of host.batch.kf.BatchKalmanFilter: each seed's x and P those of the per-seed filter).

The common path only (host.batch.tracks.base): a position update gated out for
``gate_reopen_s`` (the track starts again) and a singular innovation covariance hand the
seed back to be run per seed; a rejection, and an acceleration update re-opened, are here.
"""
from __future__ import annotations

import numpy as np

from navtwin.host.measurements import Fix, Motion
from navtwin.host.tracks.fusion import POSITION_KINDS
from navtwin.host.wsn import chi2_gate

from ..innovation import joseph_correct
from ..linalg import T, mv
from .base import BatchTrack, Columns


def lag_matrices(lag: np.ndarray) -> np.ndarray:
    """host.filters.model.lag_matrix of each lag: [I, -lag I, lag^2/2 I] (n, 2, 6)."""
    H = np.zeros((len(lag), 2, 6))
    for k, c in enumerate((np.ones_like(lag), -lag, lag * lag / 2)):
        H[:, 0, 2 * k] = H[:, 1, 2 * k + 1] = c
    return H


def _rows(a: np.ndarray, k) -> np.ndarray:
    """The rows *k* of a per-seed (n, m, ...) array; a shared (m, m) one as it is."""
    return a[k] if a.ndim == 3 else a


class BatchKfTrack(BatchTrack):
    name = "kf"
    uses_strapdown = True

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        n = ctx.n
        self.x, self.P = np.zeros((n, 6)), np.zeros((n, 6, 6))
        self._I = np.eye(6)
        self.aided = np.full(n, np.nan)  # time of the last position update; NaN: none
        self.t_predicted = np.full(n, np.nan)  # FusionTrack.t_predicted
        self._gates = {}
        self._gated_since: dict[str, np.ndarray] = {}  # kind -> first rejection of a run; NaN: none

    def handlers(self) -> dict:
        return {Motion: self.motion, Fix: self.fix}

    def _gate(self, dim: int) -> float:
        if dim not in self._gates:
            self._gates[dim] = chi2_gate(dim, self.ctx.cfg.gate_probability)
        return self._gates[dim]

    def start(self, idx, t) -> None:
        sp, sv, sa = self.ctx.cfg.p0_sigma
        self.x[idx] = [*self.ctx.cfg.start, 0.0, 0.0, 0.0, 0.0]
        self.P[idx] = np.diag([sp**2, sp**2, sv**2, sv**2, sa**2, sa**2])
        self.aided[idx] = np.nan
        self.t_predicted[idx] = t

    def sync(self, idx) -> None:
        """FusionTrack.sync: the seeds *idx* predicted to their filter time."""
        t = self.ctx.t[idx]
        behind = self.t_predicted[idx] < t
        if behind.any():
            b = idx[behind]
            self.x[b], self.P[b] = self._propagate(b, t[behind] - self.t_predicted[b])
            self.t_predicted[b] = t[behind]

    def _propagate(self, idx, dt):
        """ConstantAcceleration.propagate of the seeds *idx*, each over its dt."""
        F, Q = self.ctx.model.many(dt)
        return mv(F, self.x[idx]), np.matmul(np.matmul(F, self.P[idx]), T(F)) + Q

    def motion(self, idx, m) -> None:
        self._update(idx, m.z, m.R, m.meas.H, m.meas.dim, m.t, m.kind)

    def fix(self, idx, f) -> None:
        lag = np.maximum(self.ctx.t[idx] - f.t, 0.0)
        self._update(idx, f.p, f.cov, lag_matrices(lag), 2, f.t, "fix")

    def _update(self, idx, z, R, H, dim: int, t, kind: str) -> None:
        """FusionTrack._update: the late ones left out, the rest synced and updated, the
        gated-out ones' runs of rejections followed (module doc)."""
        ctx = self.ctx
        on = ctx.t[idx] - t <= ctx.cfg.max_lag_s
        if not on.all():
            idx, z, t, R, H = idx[on], z[on], t[on], _rows(R, on), _rows(H, on)
        if not idx.size:
            return
        self.sync(idx)
        x = self.x[idx]
        try:
            x, P, inn = joseph_correct(x, self.P[idx], self._I, z - mv(H, x), H, R, self._gate(dim))
        except np.linalg.LinAlgError:
            ctx.eject(idx, "kf: singular innovation covariance")
            return
        self.x[idx], self.P[idx] = x, P
        since = self._gated_since.setdefault(kind, np.full(ctx.n, np.nan))
        out = ~inn.accepted
        if out.any():  # the run of rejections of this kind goes on, or starts now
            r = idx[out]
            since[r] = np.where(np.isnan(since[r]), t[out], since[r])
            long = t[out] - since[r] > ctx.cfg.gate_reopen_s
            if kind in POSITION_KINDS:  # the track, not the WSN, is off: it starts again
                ctx.eject(r[long], f"{self.name}: gated out")
            elif long.any():  # the acceleration is off: its update applies ungated
                k = np.flatnonzero(out)[long]
                rows = idx[k]
                xr, Pr, _ = joseph_correct(self.x[rows], self.P[rows], self._I,
                                           z[k] - mv(_rows(H, k), self.x[rows]), _rows(H, k),
                                           _rows(R, k), None)
                self.x[rows], self.P[rows] = xr, Pr
                out[k] = False
        taken = idx[~out]
        since[taken] = np.nan
        if kind in POSITION_KINDS:
            self.aided[taken] = t[~out]

    def estimate(self, idx, b) -> Columns:
        ctx = self.ctx
        x, P = self._propagate(idx, b - self.t_predicted[idx])
        return Columns(np.ones(len(idx), bool), x[:, :2], x[:, 2:4], P[:, :4, :4],
                       ctx.stale(idx, b, self.aided[idx]), True)
