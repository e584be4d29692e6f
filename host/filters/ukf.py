"""Unscented Kalman filter on the constant-acceleration state (000 section 4, Algorithm 1).

Merwe scaled sigma points for n = 6, parameters alpha, beta, kappa::

    lambda = alpha^2 (n + kappa) - n,   L L^T = (n + lambda) P   (Cholesky)
    X_0 = x,  X_i = x + L[:, i],  X_{n+i} = x - L[:, i]
    Wm_0 = lambda / (n + lambda),  Wc_0 = Wm_0 + 1 - alpha^2 + beta,
    Wm_i = Wc_i = 1 / (2 (n + lambda))

Predict (000 eq. 14; Algorithm 1 lines 19-20): X_f = F X, x = sum Wm X_f,
P = sum Wc (X_f - x)(X_f - x)^T + Q.

Update (000 eq. 15; lines 21-22) with sigma points drawn from the current (x, P)::

    Z = h(X),  z_p = sum Wm Z,  S = sum Wc (Z - z_p)(Z - z_p)^T + R
    P_xz = sum Wc (X - x)(Z - z_p)^T,  K = P_xz S^-1
    x = x + K (z - z_p),  P = P - K S K^T

The unscented transform of a linear map is exact (the points are symmetric about x, the
weights sum to one and sum_i Wc_i (X_i - x)(X_i - x)^T = P), so for the linear motion model
and the linear acceleration measurement the UKF computes the same numbers in closed form:
x = F x, P = F P F^T + Q and the KF update with P = P - K S K^T. Only the range
measurements need the sigma points. The cross-check runs filterpy's all-sigma-point UKF
on the same inputs and agrees to 1e-9.

Variant: the sigma points of an update are drawn afresh from the current mean and
covariance. After a predict this is exactly filterpy 2.0.0, which redraws the points
from (x, P) at the end of ``predict`` (filterpy 1.4.5 reused the propagated points).
Two updates without a predict in between each see the current (x, P); filterpy would
reuse the stale prior points for the second one.
"""
from __future__ import annotations

import numpy as np

from .innovation import Innovation, gated
from .linalg import inverse
from .model import ConstantAcceleration, Linear


def merwe_weights(n: int, alpha: float, beta: float,
                  kappa: float | None) -> tuple[float, np.ndarray, np.ndarray]:
    """n + lambda (the Cholesky factor's scale), Wm and Wc (2n+1,) of the Merwe scaled sigma
    points (module doc; kappa None: 3 - n); shared with the batch twin (host.batch.ukf)."""
    kappa = 3.0 - n if kappa is None else kappa
    lam = alpha**2 * (n + kappa) - n
    Wm = np.full(2 * n + 1, 0.5 / (n + lam))
    Wc = Wm.copy()
    Wm[0] = lam / (n + lam)
    Wc[0] = lam / (n + lam) + 1.0 - alpha**2 + beta
    return n + lam, Wm, Wc


class UnscentedKalmanFilter:
    def __init__(self, x: np.ndarray, P: np.ndarray, model: ConstantAcceleration,
                 alpha: float = 1.0, beta: float = 2.0, kappa: float | None = None):
        self.x = np.array(x, dtype=float)
        self.P = np.array(P, dtype=float)
        self.model = model
        n = self.n = len(self.x)
        self.alpha, self.beta, self.kappa = alpha, beta, kappa
        self._scale, self.Wm, self.Wc = merwe_weights(n, alpha, beta, kappa)

    def sigma_points(self) -> np.ndarray:
        """(2n+1, n) sigma points of the current (x, P)."""
        U = np.linalg.cholesky(self._scale * self.P).T  # rows = columns of L
        return np.concatenate((self.x[None], self.x + U, self.x - U))

    def predict(self, dt: float) -> None:
        """The unscented transform through the linear F, in closed form (exact)."""
        self.x, self.P = self.model.propagate(self.x, self.P, dt)

    def update(self, z, R, measurement, gate: float | None = None) -> Innovation:
        """``measurement.h`` maps the (2n+1, n) sigma points to (2n+1, m); a Linear one is
        transformed in closed form (exact)."""
        R = np.asarray(R, float)
        if isinstance(measurement, Linear):
            H = measurement.H
            zp = H.dot(self.x)
            Pxz = self.P.dot(H.T)
            S = H.dot(Pxz) + R
        else:
            X = self.sigma_points()
            Z = measurement.h(X)
            zp = self.Wm.dot(Z)
            dZ = Z - zp
            WdZ = self.Wc[:, None] * dZ
            S = dZ.T.dot(WdZ) + R
            Pxz = (X - self.x).T.dot(WdZ)
        SI = inverse(S)
        y = np.asarray(z, float) - zp
        inn = gated(y, S, SI, gate)
        if inn.accepted:
            K = Pxz.dot(SI)
            self.x = self.x + K.dot(y)
            self.P = self.P - K.dot(S).dot(K.T)
        return inn
