"""``kf``: linear KF, loosely coupled (host.filters.kf): predicts at each IMU sample,
measures the SINS nav-frame acceleration and each WSN position fix (with its lag)."""
from __future__ import annotations

from navtwin.host.filters import KalmanFilter, position_fix
from navtwin.host.measurements import Fix

from .fusion import FusionTrack


class KfTrack(FusionTrack):
    name = "kf"

    def make_filter(self, x0, P0):
        return KalmanFilter(x0, P0, self.ctx.model)

    def handlers(self) -> dict:
        return {**super().handlers(), Fix: self.fix}

    def fix(self, fix: Fix) -> None:
        if fix is self.reinit_fix:
            return
        ctx = self.ctx
        self._update("fix", fix.p, fix.cov, position_fix(max(ctx.t - fix.t, 0.0)), fix.t)
