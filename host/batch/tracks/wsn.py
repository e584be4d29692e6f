"""``wsn``'s twin (host.tracks.wsn): the latest fix, the velocity of the last two."""
from __future__ import annotations

import numpy as np

from .base import BatchTrack, Columns


class BatchWsnTrack(BatchTrack):
    name = "wsn"

    def estimate(self, idx: np.ndarray, b: np.ndarray) -> Columns:
        ctx, ranging = self.ctx, self.ctx.ranging
        t0, t1 = ranging.fix_t[idx, 0], ranging.fix_t[idx, 1]
        valid = ~np.isnan(t0)  # two fixes
        p0, p1 = ranging.fix_p[idx, 0], ranging.fix_p[idx, 1]
        c0, c1 = ranging.fix_cov[idx, 0], ranging.fix_cov[idx, 1]
        dt = np.where(valid, t1 - t0, 1.0)
        v = (p1 - p0) / dt[:, None]
        cov = np.empty((len(idx), 4, 4))  # [[C1, C1/dt], [C1/dt, (C0 + C1)/dt^2]]
        cov[:, :2, :2] = c1
        cov[:, :2, 2:] = cov[:, 2:, :2] = c1 / dt[:, None, None]
        cov[:, 2:, 2:] = (c0 + c1) / (dt**2)[:, None, None]
        return Columns(valid, p1, v, cov, ctx.stale(idx, b, t1), False)
