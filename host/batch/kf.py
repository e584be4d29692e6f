"""The linear Kalman filter of host.filters.kf for N seeds along a leading axis.

Predict (000 eq. 14), per seed::

    x = F(dt) x,    P = F(dt) P F(dt)^T + Q(dt)

with F and Q of the estimator's ConstantAcceleration model (its own ``F`` and ``Q``, one
shared dt or a dt per seed). Update: the gated Joseph form of host.batch.innovation with a
Linear measurement (z = H x, H shared by the seeds: the SINS acceleration, a WSN fix).
Each seed's x and P equal KalmanFilter's stepped alone, bit for bit (tests/host/test_batch.py).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from navtwin.host.filters.model import ConstantAcceleration, Linear

from .innovation import BatchInnovation
from .linalg import T, mv
from .base import BatchFilter
from .seeds import take


def propagate(x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray):
    """F x and F P F^T + Q of the seeds' x (k, n), P (k, n, n); F, Q shared or per seed."""
    return mv(F, x), np.matmul(np.matmul(F, P), T(F)) + Q


class BatchKalmanFilter(BatchFilter):
    """x (N, n) and P (N, n, n) of N seeds on one motion *model*."""

    def __init__(self, x, P, model: ConstantAcceleration):
        super().__init__(x, P)
        self.model = model
        self._I = np.eye(self.x.shape[1])
        # F and Q of a shared dt, cached: the IMU period recurs (as in the model itself)
        self._transition = lru_cache(maxsize=32)(self._build)

    def _build(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        return self.model.F(dt), self.model.Q(dt)

    def predict(self, dt, active=None) -> None:
        """Over dt (one value, or (N,) per seed) for the *active* seeds (None: all)."""
        idx = self.chosen(active)
        dt = take(self.given(dt, 0, "dt"), 0, idx)
        if dt.ndim:  # a dt per seed: every seed's F and Q at once (the same numbers)
            F, Q = self.model.many(dt)
        else:
            F, Q = self._transition(float(dt))
        x, P = self.rows(idx)
        self.store(idx, *propagate(x, P, F, Q))

    def update(self, z, R, measurement: Linear, gate=None, active=None) -> BatchInnovation:
        """Correct the *active* seeds with z (N, m) = H x + v, v ~ N(0, R) (R (m, m) or
        (N, m, m)); a seed whose NIS exceeds *gate* (None, one value or (N,)) is unchanged."""
        if not isinstance(measurement, Linear):
            raise TypeError(f"BatchKalmanFilter needs a Linear measurement, got "
                            f"{type(measurement).__name__}")
        return self.correct(z, measurement.H, R, gate, active)
