"""``ekf``: EKF, tightly coupled (host.filters.ekf): the KF's prediction and acceleration
update; measures each cycle's range differences to the reference anchor (``[filters.ekf]
tight = "toa"``: each range at its own time), linearised at the prior."""
from __future__ import annotations

from navtwin.host.filters import ExtendedKalmanFilter

from .fusion import TightTrack


class EkfTrack(TightTrack):
    name = "ekf"

    def make_filter(self, x0, P0):
        return ExtendedKalmanFilter(x0, P0, self.ctx.model)
