"""``tc``'s twin (host.tracks.tc): the closed-loop error state (host.batch.tracks.errorstate)
plus the NLOS random-walk states, one scalar update per range (001 eqs. 22-24)::

    z = rho_INS,i - rho_WSN,i,  H = [u_i^T, lead u_i^T, 0 0 0, -1 at e_i],  R = R(rho_WSN,i)

for the rows of many seeds, each with its own anchor i (RangeBatch.row); e_i is the
anchor's state, or the one shared by all (``nlos_states = "shared"``)."""
from __future__ import annotations

import numpy as np

from navtwin.host.filters.errorstate import NAV
from navtwin.host.measurements import Range
from navtwin.host.tracks.tc import TcTrack

from .errorstate import BatchErrorStateTrack


class BatchTcTrack(BatchErrorStateTrack):
    name = "tc"
    Track = TcTrack

    def handlers(self) -> dict:
        return {**super().handlers(), Range: self.range}

    def range(self, idx, m) -> None:
        ok = self.ready(idx, m.t)
        idx, t, rho_wsn, row = idx[ok], m.t[ok], m.z[ok], m.row[ok]
        if not idx.size:
            return
        p, lead = self.position_at(idx, t)
        r, u = self.ctx.layout.geometry(p, row)  # one position per range: row k's anchor
        k = np.arange(len(idx))
        H = np.zeros((len(idx), 1, self.x.shape[1]))
        H[:, 0, 0:2] = u
        H[:, 0, 2:4] = lead[:, None] * u
        H[k, 0, NAV + (0 if self.settings.nlos_states == "shared" else row)] = -1.0
        R = self.one.variances(rho_wsn)[:, None, None]
        self.update(idx, t, (r - rho_wsn)[:, None], H, R, 1)
