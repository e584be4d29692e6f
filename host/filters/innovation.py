"""The innovation of one update and its chi-square gate (shared by KF, EKF, UKF).

Gate: the squared Mahalanobis distance NIS = y^T S^-1 y of a consistent innovation is
chi-square with dim(z) degrees of freedom; an update with NIS above the gate (e.g. the
99.99 % quantile, ``host.wsn.chi2_gate``) is rejected and leaves the filter unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class Innovation:
    y: np.ndarray  # z - h(x_prior)
    S: np.ndarray  # its covariance
    nis: float  # y^T S^-1 y
    accepted: bool


def inverse(S: np.ndarray) -> np.ndarray:
    """S^-1; 1x1 and 2x2 (every range and acceleration update) in closed form, for speed."""
    m = S.shape[0]
    if m == 1:
        return 1.0 / S
    if m == 2:
        a, b, c, d = S[0, 0], S[0, 1], S[1, 0], S[1, 1]
        return np.array([[d, -b], [-c, a]]) / (a * d - b * c)
    return np.linalg.inv(S)


def gated(y: np.ndarray, S: np.ndarray, SI: np.ndarray, gate: float | None) -> Innovation:
    nis = float(y @ SI @ y)
    return Innovation(y, S, nis, gate is None or nis <= gate)
