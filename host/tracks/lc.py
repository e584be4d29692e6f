"""``lc``: 001's loosely coupled SINS/WSN filter (section 2, eqs. 1-12): the closed-loop
error state (host.tracks.errorstate) measures the WSN position fix, z = p_SINS - p_WSN
(eq. 11) with H = [I, lead I, 0] (eq. 12 and the fix's time, host.tracks.errorstate) and
R = the fix's covariance. A cycle without a fix (fewer than three ranges, or refused)
gives no update: the strapdown coasts on its last correction."""
from __future__ import annotations

import numpy as np

from navtwin.host.filters.errorstate import NAV
from navtwin.host.measurements import Fix

from .errorstate import ErrorStateTrack


class LcTrack(ErrorStateTrack):
    name = "lc"

    def handlers(self) -> dict:
        return {**super().handlers(), Fix: self.fix}

    def fix(self, fix: Fix) -> None:
        if fix is self.reinit_fix or not self.ready(fix.t):
            return
        p, lead = self.position_at(fix.t)
        H = np.zeros((2, NAV))
        H[0, 0] = H[1, 1] = 1.0
        H[0, 2] = H[1, 3] = lead
        self._update("fix", fix.t, p - fix.p, H, fix.cov, 2)
