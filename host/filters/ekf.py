"""Extended Kalman filter on the constant-acceleration state (000 section 4).

The motion model is linear, so the prediction is the KF's (000 eq. 14). A nonlinear
measurement z = h(x) + v (000 eq. 15: ranges, eqs. 10-11, or range differences to
anchor 1, eqs. 12-13) is linearised at the prior::

    H = dh/dx (x),  y = z - h(x),  S = H P H^T + R,  K = P H^T S^-1
    x = x + K y,    P = (I - K H) P (I - K H)^T + K R K^T        (Joseph form)

This is filterpy's ``ExtendedKalmanFilter.update(z, HJacobian, Hx, R)`` (cross-checked to
1e-9). For a linear measurement h(x) = H x it is exactly the KF update.
"""
from __future__ import annotations

import numpy as np

from .innovation import Innovation
from .kf import KalmanFilter


class ExtendedKalmanFilter(KalmanFilter):
    def update(self, z, R, measurement, gate: float | None = None) -> Innovation:
        """``measurement.linearize(x)`` gives h(x) and dh/dx(x) (host.filters.model)."""
        hx, H = measurement.linearize(self.x)
        return self._correct(np.asarray(z, float) - hx, H, np.asarray(R, float), gate)
