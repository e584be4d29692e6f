"""``sins``'s twin (host.tracks.sins): the estimator's strapdown reported, its covariance the
initial one plus the accelerometer's velocity random walk since the alignment."""
from __future__ import annotations

import numpy as np

from navtwin.host.tracks.sins import SinsSettings

from .base import BatchTrack, Columns


class BatchSinsTrack(BatchTrack):
    name = "sins"
    uses_strapdown = True

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings or SinsSettings())

    def estimate(self, idx: np.ndarray, b: np.ndarray) -> Columns:
        ctx = self.ctx
        n = len(idx)
        sp, sv, _ = ctx.cfg.p0_sigma
        pp, pv, vv = np.full(n, float(sp) ** 2), np.zeros(n), np.full(n, float(sv) ** 2)
        p = np.tile(np.asarray(ctx.cfg.start, float), (n, 1))
        v = np.zeros((n, 2))
        on = ctx.aligned[idx]
        if on.any():
            s = idx[on]
            dt = b[on] - ctx.t_imu[s]
            v[on] = ctx.sins.v[s, :2]
            p[on] = ctx.sins.p[s, :2] + v[on] * dt[:, None]
            T = b[on] - ctx.t_aligned[s]
            q = (self.settings.vrw_m_s_rt_hr / 60.0) ** 2
            pp[on], pv[on], vv[on] = pp[on] + q * (T**3 / 3), pv[on] + q * (T**2 / 2), vv[on] + q * T
        z = np.zeros(n)
        cov = np.stack([pp, z, pv, z, z, pp, z, pv, pv, z, vv, z, z, pv, z, vv], 1).reshape(n, 4, 4)
        return Columns(np.ones(n, bool), p, v, cov, ctx.stale(idx, b, ctx.t_imu[idx]), True)
