"""``lc``'s twin (host.tracks.lc): the closed-loop error state (host.batch.tracks.errorstate)
measuring each WSN fix, z = p_SINS - p_WSN with H = [I, lead I, 0] and R = the fix's
covariance (001 eqs. 11-12), for the rows of many seeds."""
from __future__ import annotations

import numpy as np

from navtwin.host.filters.errorstate import NAV
from navtwin.host.measurements import Fix
from navtwin.host.tracks.lc import LcTrack

from .errorstate import BatchErrorStateTrack


class BatchLcTrack(BatchErrorStateTrack):
    name = "lc"
    Track = LcTrack

    def handlers(self) -> dict:
        return {**super().handlers(), Fix: self.fix}

    def fix(self, idx, f) -> None:
        """LcTrack.fix, after the fix is offered (a track that started again at it takes no
        update from it)."""
        ok = self.ready(idx, f.t) & ~self.offer_fix(idx, f)
        idx, t = idx[ok], f.t[ok]
        if not idx.size:
            return
        p, lead = self.position_at(idx, t)
        H = np.zeros((len(idx), 2, NAV))
        H[:, 0, 0] = H[:, 1, 1] = 1.0
        H[:, 0, 2] = H[:, 1, 3] = lead
        self.update(idx, t, p - f.p[ok], H, f.cov[ok], 2)
