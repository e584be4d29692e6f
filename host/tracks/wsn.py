"""``wsn``: the pure WSN track (host.wsn): one TDOA (``wsn_method = "toa"``: TOA) fix per
TDMA cycle (000 eqs. 6-13), made by the estimator (the fusion tracks use the fixes too).

Emits the latest fix with its CRLB covariance and the velocity of the last two fixes
(finite difference) with its propagated covariance; it starts once two fixes exist, and a
device restart drops its velocity history. Yaw: None. Extrapolated: no fix for
``extrapolated_after_s``.
"""
from __future__ import annotations

import numpy as np

from navtwin.host.measurements import FixRefused
from navtwin.host.measurements import Fix

from .base import Track, estimate


class WsnTrack(Track):
    name = "wsn"

    def handlers(self) -> dict:
        return {Fix: self.fix, FixRefused: self.refused}

    def fix(self, fix: Fix) -> None:
        self.updates["fix"] += 1
        if fix.dropped:
            self.rejections["outlier_dropped"] += 1

    def refused(self, m: FixRefused) -> None:
        self.rejections[m.reason] += 1

    def restart(self, device: str, t: float) -> None:
        if self.ctx.fixes:
            self.count_reinit("restart")

    def estimate(self, b: float, yaw: float):
        fixes = self.ctx.fixes
        if len(fixes) < 2:
            return None
        f0, f1 = fixes
        dt = f1.t - f0.t
        v = (f1.p - f0.p) / dt
        cov = np.empty((4, 4))  # [[C1, C1/dt], [C1/dt, (C0 + C1)/dt^2]]
        cov[:2, :2] = f1.cov
        cov[:2, 2:] = cov[2:, :2] = f1.cov / dt
        cov[2:, 2:] = (f0.cov + f1.cov) / dt**2
        return estimate(b, self.name, f1.p, v, None, cov, self.ctx.stale(b, f1.t))
