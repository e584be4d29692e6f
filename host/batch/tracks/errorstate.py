"""What the twins of 001's tracks (lc, tc, fatci) share: host.tracks.errorstate's
ErrorStateTrack (with ClosedLoopTrack and OwnStrapdown) for the rows of many seeds.

Each seed has a strapdown of its own (host.batch.strapdown.BatchStrapdown rows, ``nav``): its
row is taken from the estimator's at the IMU sample that ends the alignment, then stepped
with every sample (the same samples, the same integration; the estimator steps it, with its
own and the other tracks', in one call: :meth:`own_step`) and the error state predicted over
each step with that step's specific force f_n (001 eq. 27; host.batch.errorstate.propagate, each
seed over its own interval). A measurement at t is compared with the strapdown extrapolated
over t - t_nav (``position_at``); the gated Joseph update (host.batch.innovation) of the
rows it accepts is fed back into their strapdowns (``take_nav`` then ``correct``: 001 sect.
2, closed loop) and the nav part of x reset. An estimate is the strapdown extrapolated to
the output instant, its covariance F P F^T with F = [[I, lead I], [0, I]] on (p, v).

The common path, with the track's own discontinuity: every update gated out for
``gate_reopen_s`` turns the track off (``gated``) until the next WSN fix no older than that,
at which it starts again (ErrorStateTrack.reinit_at: the strapdown placed at the fix, at
rest, the attitude kept; P of position and velocity from the fix and ``reinit_sigma``, the
attitude's and the extra states' kept), taking no other update of that fix; meanwhile its
strapdown runs on and its estimates are extrapolated. A singular innovation covariance (a
numerical reset) hands the seed back (host.batch.tracks.base); a restart or a gap never
reaches a twin (the engine ejects the seed first).

The constants (noise densities, P0, the extra states, R of a range) are the per-seed
track's own: the twin builds one (``one``) from the same settings and reads them there.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import ClassVar

import numpy as np

from navtwin.host.filters.errorstate import NAV
from navtwin.host.measurements import Fix, ImuSample
from navtwin.host.tracks.errorstate import ErrorStateTrack
from navtwin.host.wsn import chi2_gate

from ..errorstate import propagate
from ..innovation import joseph_correct
from ..linalg import T, mv
from ..seeds import whole
from ..strapdown import BatchStrapdown
from .base import BatchTrack, Columns


class BatchErrorStateTrack(BatchTrack):
    """The twin of ``Track`` (an ErrorStateTrack) for the rows of ``ctx.n`` seeds."""

    uses_strapdown = own_strapdown = True
    nav: BatchStrapdown  # given by the estimator (host.batch.tracks.base)
    Track: ClassVar[type[ErrorStateTrack]]

    def __init__(self, ctx, settings=None) -> None:
        cfg = ctx.cfg
        # the per-seed track, for its constants: its settings, noise, P0 and extra states
        self.one = one = self.Track(SimpleNamespace(cfg=cfg, layout=ctx.layout,
                                                    calibration=cfg.calibration), settings)
        super().__init__(ctx, one.settings)
        one.started(0.0)  # its fresh filter: P0 and the noise densities
        self._P0 = one.filter.P
        self._noise = one.filter.noise
        n, m = ctx.n, NAV + one.extra
        self.on = np.zeros(n, bool)  # has its strapdown (the alignment ended)
        self.t_nav = np.full(n, np.nan)
        self.x, self.P = np.zeros((n, m)), np.zeros((n, m, m))
        self._I = np.eye(m)
        self.aided = np.full(n, np.nan)  # the last accepted update; NaN: none
        self.gated_since = np.full(n, np.nan)  # the first rejection of a run; NaN: none
        self.reinit_since = np.full(n, np.nan)  # Track.reinit_since; NaN: running
        self.reinit_fix = np.zeros(n, np.int64)  # Track.reinit_fix: the number of the fix it
        # last started again at (host.batch.ranging; 0: none)

    def handlers(self) -> dict:
        return {ImuSample: self.imu, Fix: self.offer_fix}

    def offer_fix(self, idx, f) -> np.ndarray:
        """Track.offer_fix with ErrorStateTrack.reinit_at: the seeds waiting since a
        discontinuity no later than the fix start again at it (module doc); which did."""
        at = (f.t >= self.reinit_since[idx]) & self.on[idx]  # NaN: not waiting
        if at.any():
            rows = idx[at]
            sv, _ = self.ctx.cfg.reinit_sigma
            self.nav.place(rows, f.p[at], np.zeros((len(rows), 2)))
            P = np.zeros(self.P[rows].shape)
            P[:, :2, :2] = f.cov[at]
            P[:, 2, 2] = P[:, 3, 3] = sv**2
            P[:, 4:, 4:] = self.P[rows, 4:, 4:]
            self.P[rows] = P
            self.x[rows, :NAV] = 0.0
            self.gated_since[rows] = np.nan
            self.aided[rows] = f.t[at]
            self.reinit_since[rows] = np.nan
            self.reinit_fix[rows] = f.number[at]
        return at

    # -- the strapdown and the predict --------------------------------------------------------
    def own_step(self, idx, t) -> tuple[np.ndarray, np.ndarray]:
        """OwnStrapdown.imu's step: the seeds whose strapdown started before this sample; the
        stream's samples are strictly in order, so dt > 0 on every one."""
        on = self.on[idx]
        return on, t[on] - self.t_nav[idx[on]]

    def imu(self, idx, b) -> None:
        """OwnStrapdown.imu and ErrorStateTrack.stepped for the seeds *idx* (an ImuBatch),
        their strapdowns stepped with the sample already (:meth:`own_step`)."""
        aligned = self.ctx.aligned[idx]
        if not aligned.any():
            return
        idx, t = idx[aligned], b.t[aligned]
        new = ~self.on[idx]
        if new.any():  # the alignment ended with this sample: start from its strapdown
            s = idx[new]
            self.nav.take(s, self.ctx.sins)
            self.t_nav[s] = t[new]
            self.on[s] = True
            self.x[s], self.P[s] = 0.0, self._P0
        old = ~new
        if old.any():
            s = whole(idx[old], len(self.on))
            dt = t[old] - self.t_nav[s]
            self.t_nav[s] = t[old]
            self.P[s] = propagate(self.P[s], dt, self.nav.f_n[s], self._noise)

    # -- updates ----------------------------------------------------------------------------
    def ready(self, idx, t) -> np.ndarray:
        """ClosedLoopTrack.ready of the seeds *idx* for measurements at t: whether each can
        update (a late one is counted there, and changes nothing)."""
        return self.on[idx] & np.isnan(self.reinit_since[idx]) & \
            ~(self.t_nav[idx] - t > self.ctx.cfg.max_lag_s)

    def position_at(self, idx, t) -> tuple[np.ndarray, np.ndarray]:
        """The strapdowns' horizontal positions extrapolated to t (n, 2), and t - t_nav (n,)."""
        lead = t - self.t_nav[idx]
        return self.nav.p[idx, :2] + lead[:, None] * self.nav.v[idx, :2], lead

    def update(self, idx, t, z, H, R, dof: int) -> None:
        """ClosedLoopTrack._update of the seeds *idx*: z (n, dof), H (n, dof, m), R (n, dof,
        dof); the accepted ones fed back into their strapdowns (ErrorStateTrack.feed_back)."""
        ctx = self.ctx
        x = self.x[idx]
        try:
            x, P, inn = joseph_correct(x, self.P[idx], self._I, z - mv(H, x), H, R,
                                       chi2_gate(dof, ctx.cfg.gate_probability))
        except np.linalg.LinAlgError:
            ctx.eject(idx, f"{self.name}: singular innovation covariance")
            return
        out = ~inn.accepted
        if out.any():  # the run of rejections goes on, or starts now; too long: the track is off
            r = idx[out]
            since = self.gated_since[r] = np.where(np.isnan(self.gated_since[r]), t[out],
                                                   self.gated_since[r])
            off = t[out] - since > ctx.cfg.gate_reopen_s  # Track.discontinuity("gated", t)
            self.reinit_since[r[off]] = t[out][off]
        a = ~out
        if not a.any():
            return
        rows = idx[a]
        dx = x[a, :NAV].copy()
        x[a, :NAV] = 0.0
        self.x[rows], self.P[rows] = x[a], P[a]
        self.nav.correct(rows, dx[:, 0:2], dx[:, 2:4], dx[:, 4:7])
        self.gated_since[rows] = np.nan
        self.aided[rows] = t[a]

    # -- output -----------------------------------------------------------------------------
    def estimate(self, idx, b) -> Columns:
        ctx = self.ctx
        n = len(idx)
        sp, sv, _ = ctx.cfg.p0_sigma
        # before its strapdown (Track.unstarted): at the start, at rest, P0's sigmas
        p = np.tile(np.asarray(ctx.cfg.start, float), (n, 1))
        v = np.zeros((n, 2))
        cov = np.tile(np.diag([sp**2, sp**2, sv**2, sv**2]), (n, 1, 1))
        yaw = np.full(n, ctx.cfg.heading_rad)
        on = self.on[idx]
        if on.any():
            s = idx[on]
            lead = b[on] - self.t_nav[s]
            v[on] = self.nav.v[s, :2]
            p[on] = self.nav.p[s, :2] + lead[:, None] * v[on]
            F = np.tile(np.eye(4), (len(s), 1, 1))
            F[:, 0, 2] = F[:, 1, 3] = lead
            cov[on] = np.matmul(np.matmul(F, self.P[s, :4, :4]), T(F))
            yaw[on] = self.nav.yaw(s)
        stale = ~np.isnan(self.reinit_since[idx]) | ctx.stale(idx, b, self.aided[idx])
        return Columns(np.ones(n, bool), p, v, cov, stale, True, yaw)
