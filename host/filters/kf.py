"""Linear Kalman filter on the constant-acceleration state (000 section 4).

Predict (000 eq. 14)::

    x = F x,    P = F P F^T + Q

Update with a linear measurement z = H x + v, v ~ N(0, R) (000 eq. 15), Joseph form::

    y = z - H x,  S = H P H^T + R,  K = P H^T S^-1
    x = x + K y,  P = (I - K H) P (I - K H)^T + K R K^T

The Joseph form keeps P symmetric and positive definite whatever the rounding, and is
what filterpy's ``KalmanFilter.update`` computes (the cross-check matches it to 1e-9).
An innovation whose NIS exceeds ``gate`` is rejected: the state is left unchanged.

In the fusion (host.estimator) the KF is loosely coupled: it measures the SINS
nav-frame acceleration (H = [0 0 I]) and the WSN TOA position fix (H = [I 0 0], with a
lag term for the fix's age), see docs/filters.md.
"""
from __future__ import annotations

import numpy as np

from .innovation import Innovation, joseph_correct
from .model import ConstantAcceleration, Linear


class KalmanFilter:
    def __init__(self, x: np.ndarray, P: np.ndarray, model: ConstantAcceleration):
        self.x = np.array(x, dtype=float)
        self.P = np.array(P, dtype=float)
        self.model = model
        self._I = np.eye(len(self.x))

    def predict(self, dt: float) -> None:
        self.x, self.P = self.model.propagate(self.x, self.P, dt)

    def update(self, z, R, measurement: Linear, gate: float | None = None) -> Innovation:
        if not isinstance(measurement, Linear):
            raise TypeError(f"KalmanFilter needs a Linear measurement, got {type(measurement).__name__}")
        H = measurement.H
        return self._correct(np.asarray(z, float) - H.dot(self.x), H, np.asarray(R, float), gate)

    def _correct(self, y: np.ndarray, H: np.ndarray, R: np.ndarray, gate: float | None) -> Innovation:
        self.x, self.P, inn = joseph_correct(self.x, self.P, self._I, y, H, R, gate)
        return inn
