"""The innovation of one update and its chi-square gate (shared by KF, EKF, UKF).

Gate: the squared Mahalanobis distance NIS = y^T S^-1 y of a consistent innovation is
chi-square with dim(z) degrees of freedom; an update with NIS above the gate (e.g. the
99.99 % quantile, ``host.wsn.chi2_gate``) is rejected and leaves the filter unchanged.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .linalg import inverse


class Innovation(NamedTuple):  # a tuple: one is made per update, 20 000 a minute
    y: np.ndarray  # z - h(x_prior)
    S: np.ndarray  # its covariance
    nis: float  # y^T S^-1 y
    accepted: bool


def gated(y: np.ndarray, S: np.ndarray, SI: np.ndarray, gate: float | None) -> Innovation:
    nis = float(y.dot(SI).dot(y))
    return Innovation(y, S, nis, gate is None or nis <= gate)


def joseph_correct(x: np.ndarray, P: np.ndarray, I: np.ndarray, y: np.ndarray, H: np.ndarray,
                   R: np.ndarray, gate: float | None) -> tuple[np.ndarray, np.ndarray, Innovation]:
    """The linear update of innovation y = z - H x with the Joseph form of P (symmetric and
    positive for any gain: P = (I - KH) P (I - KH)^T + K R K^T); x and P unchanged when the
    gate rejects it. *I* is the identity of P's size (kept by the caller: 20 000 a minute)."""
    PHT = P.dot(H.T)
    S = H.dot(PHT) + R
    SI = inverse(S)
    inn = gated(y, S, SI, gate)
    if inn.accepted:
        K = PHT.dot(SI)
        x = x + K.dot(y)
        I_KH = I - K.dot(H)
        P = I_KH.dot(P).dot(I_KH.T) + K.dot(R).dot(K.T)
    return x, P, inn
