"""The UKF update of host.filters.ukf for N seeds along a leading axis.

Per seed (host.filters.ukf's module doc; Merwe scaled sigma points drawn from the current
(x, P), weights of :func:`navtwin.host.filters.ukf.merwe_weights`)::

    L L^T = (n + lambda) P,  X = [x, x + L_i, x - L_i]
    Z = h(X),  z_p = Wm Z,  S = sum Wc (Z - z_p)(Z - z_p)^T + R,  P_xz = sum Wc (X - x)(Z - z_p)^T
    K = P_xz S^-1,  x = x + K (z - z_p),  P = P - K S K^T

and for a linear measurement (host.batch.model.BatchLinear) the transform in closed form:
z_p = H x, P_xz = P H^T, S = H P_xz + R. Each product is the per-seed filter's on stacked
operands (host.batch.linalg), the Cholesky factor LAPACK's potrf per seed as for one filter,
so each seed's x and P are its own filter's. A seed whose NIS exceeds the gate keeps its
x and P.
"""
from __future__ import annotations

import numpy as np

from .innovation import BatchInnovation, gated, projected
from .linalg import T, inverse, mv, selection
from .model import BatchLinear, hx


def sigma_points(x: np.ndarray, P: np.ndarray, scale: float) -> np.ndarray:
    """(n, 2k+1, k) sigma points of each seed's (x, P); LinAlgError if a P is not positive
    definite."""
    U = T(np.linalg.cholesky(scale * P))  # rows = columns of L
    x = x[:, None]
    return np.concatenate((x, x + U, x - U), 1)


def unscented_correct(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray, meas, gate,
                      weights: tuple[float, np.ndarray, np.ndarray]
                      ) -> tuple[np.ndarray, np.ndarray, BatchInnovation]:
    """The update of x (N, n), P (N, n, n) with z (N, m) through *meas* (host.batch.model), R
    (m, m) or (N, m, m), gate None or one value; *weights*: (n + lambda, Wm, Wc). Returns the
    new x and P (the rejected seeds' unchanged) and the innovations."""
    if isinstance(meas, BatchLinear):
        H = meas.H
        zp = hx(H, x)
        Pxz, S = projected(P, H, R, selection(H))
    else:
        scale, Wm, Wc = weights
        X = sigma_points(x, P, scale)
        Z = meas.h(X)
        zp = np.matmul(Wm, Z)
        dZ = Z - zp[:, None]
        WdZ = Wc[:, None] * dZ
        S = np.matmul(T(dZ), WdZ) + R
        Pxz = np.matmul(T(X - x[:, None]), WdZ)
    SI = inverse(S)
    y = z - zp

    def correct(rows, a):
        K = np.matmul(rows(Pxz), rows(SI))
        return rows(x) + mv(K, rows(y)), rows(P) - np.matmul(np.matmul(K, rows(S)), T(K))

    return gated(x, P, y, S, SI, gate, correct)
