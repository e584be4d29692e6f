"""The innovation of one update and its chi-square gate (shared by KF, EKF, UKF).

Gate: the squared Mahalanobis distance NIS = y^T S^-1 y of a consistent innovation is
chi-square with dim(z) degrees of freedom; an update with NIS above the gate (e.g. the
99.99 % quantile, ``host.wsn.chi2_gate``) is rejected and leaves the filter unchanged.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Innovation(NamedTuple):  # a tuple: one is made per update, 20 000 a minute
    y: np.ndarray  # z - h(x_prior)
    S: np.ndarray  # its covariance
    nis: float  # y^T S^-1 y
    accepted: bool


def gated(y: np.ndarray, S: np.ndarray, SI: np.ndarray, gate: float | None) -> Innovation:
    nis = float(y.dot(SI).dot(y))
    return Innovation(y, S, nis, gate is None or nis <= gate)
