"""Inputs along the seed axis: shared by every seed (their core shape, e.g. R (m, m)) or
given per seed (one more leading axis, R (N, m, m)), and what depends on dt built once per
distinct value.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np


def take(value: np.ndarray, core_ndim: int, idx: np.ndarray | None) -> np.ndarray:
    """*value*'s rows of the seeds *idx* if it is given per seed (core_ndim + 1 axes), else
    *value* (shared by every seed)."""
    if idx is None or value.ndim == core_ndim:
        return value
    return value[idx]


def by_dt(dt: np.ndarray, build: Callable[[float], np.ndarray]) -> np.ndarray:
    """``build(dt)`` for a shared dt; for dt per seed (N,), each seed's ``build`` stacked
    (N, ...), built once per distinct value (the IMU period recurs: a few values)."""
    if dt.ndim == 0:
        return build(float(dt))
    values, which = np.unique(dt, return_inverse=True)
    # no seed in the step: build(0.0) gives the (0, ...) stack its shape
    return np.stack([build(float(v)) for v in values] or [build(0.0)])[which]
