"""``kf``'s twin (host.tracks.kf): the linear KF of host.batch.tracks.fusion, measuring the
Motion product and each WSN fix with its lag (the fix's H per seed:
host.batch.model.position_fixes)."""
from __future__ import annotations

import numpy as np

from navtwin.host.measurements import Fix

from ..model import position_fixes
from .fusion import BatchFusionTrack


class BatchKfTrack(BatchFusionTrack):
    name = "kf"

    def handlers(self) -> dict:
        return {**super().handlers(), Fix: self.fix}

    def fix(self, idx, f) -> None:
        """The fix is offered first; a seed that started again at it takes nothing else of it."""
        on = ~self.offer_fix(idx, f)
        if not on.all():
            idx = idx[on]
            f = f._replace(t=f.t[on], p=f.p[on], cov=f.cov[on], number=f.number[on])
        lag = np.maximum(self.ctx.t[idx] - f.t, 0.0)
        self._update(idx, f.p, f.cov, position_fixes(lag), f.t, "fix")
