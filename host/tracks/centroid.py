"""``centroid`` and ``wcl``: 003's RSSI centroid and weighted-centroid fixes aiding the SINS
(003 sections 2.1-2.2 and 3; docs/filters.md, "003's tracks").

Each TDMA cycle (host.wsn.CycleGrouper, ``cycle_s``) of the gateway's reports gives, from
each completed exchange's RSSI byte, a distance by the path-loss model inverted (003 eq. 2,
host.rssi.distance, with ``rssi_1m_dbm`` and ``path_loss_exponent``); the three strongest
anchors' distances, made horizontal with the tag height (r_h^2 = d^2 - dz^2), give the fix:
the centroid of 003's three circle points A, B, C (eqs. 9-10, ``centroid``) or their
weighted centroid (eqs. 11-12, ``wcl``; host.centroid). The fix aids the SINS as 001's lc
does (host.tracks.lc: z = p_SINS - p_fix, H = [I, lead I, 0]; in place of 003 eqs. 17-20's
range differences of both positions, their linear map), R = fix_sigma_m^2 I: 003 gives its
fix no covariance. A cycle with fewer than three RSSI distances, or whose fix is
refused, gives no update (counted by reason).

Not here yet (issue 20 item 4's rest): 003's 15-state geodetic error state and the
magnetometer heading (eqs. 13-16, 21-24), and the adaptive parameters (eqs. 3-8, host.rssi) in the track: they
need the anchors' readings of each other, which the gateway does not report.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import between, key, positive
from navtwin.host import centroid, rssi
from navtwin.host.measurements import Exchange, Fix
from navtwin.host.wsn import CycleGrouper
from navtwin.protocols.nanoloc import is_complete

from .errorstate import ErrorStateSettings
from .lc import LcTrack


@dataclass(frozen=True)
class CentroidSettings(ErrorStateSettings):
    rssi_1m_dbm: float = key(-45.0, "dBm", "RSSI(1 m) of the path-loss model (003 eq. 2's "
                             "RSSI(1), eq. 8's lambda)", between(-120, 20))
    path_loss_exponent: float = key(2.0, "", "path-loss exponent n of 003 eq. 2", between(1, 6))
    fix_sigma_m: float = key(1.5, "m", "1 sigma per axis of the RSSI fix: R = fix_sigma_m^2 I "
                             "(003 gives none)", positive(hi=1e3))


class CentroidTrack(LcTrack):
    name = "centroid"
    Settings = CentroidSettings
    #: The fix of three anchors' circles (host.centroid): eqs. 9-10.
    locate = staticmethod(centroid.centroid)

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.grouper = CycleGrouper(len(ctx.layout.ids), ctx.cfg.cycle_s)

    def handlers(self) -> dict:
        taken = {**super().handlers(), Exchange: self.exchange}
        del taken[Fix]  # its own fixes, from the RSSI, not the WSN's
        return taken

    def restart(self, device: str, t: float) -> None:
        super().restart(device, t)
        if device == "anchors":  # no cycle spans a restart
            self.grouper = CycleGrouper(len(self.ctx.layout.ids), self.ctx.cfg.cycle_s)

    def exchange(self, rec: Exchange) -> None:
        s = self.settings
        # a timed-out or incomplete exchange's RSSI byte measured no reply
        d = rssi.distance(rec.rssi, s.rssi_1m_dbm, s.path_loss_exponent) if is_complete(rec.status) else None
        for cycle in self.grouper.add(rec.t, rec.anchor, None if d is None else float(d)):
            self.cycle(cycle)

    def cycle(self, cycle) -> None:
        """A closed cycle's fix of its three strongest anchors, and the update it gives."""
        if len(cycle.distances) < 3:
            self.rejections["few_anchors"] += 1
            return
        nearest = np.argsort(cycle.distances, kind="stable")[:3]
        anchors = tuple(cycle.valid_anchors[k] for k in nearest)
        layout = self.ctx.layout
        idx = layout.index(anchors)
        slant = np.asarray(cycle.distances)[nearest]
        res = self.locate(layout.xy[idx], np.sqrt(np.maximum(slant**2 - layout.dz[idx] ** 2, 0.0)))
        if res.p is None:
            self.rejections[res.reason] += 1
            return
        self.fix(Fix(cycle.t, res.p, self.settings.fix_sigma_m**2 * np.eye(2), anchors, 0.0))


class WclTrack(CentroidTrack):
    name = "wcl"
    #: The weighted centroid (host.centroid): eqs. 11-12.
    locate = staticmethod(centroid.weighted_centroid)
