"""Inputs along the seed axis: shared by every seed (their core shape, e.g. R (m, m)) or
given per seed (one more leading axis, R (N, m, m)).
"""
from __future__ import annotations

import numpy as np


def take(value: np.ndarray, core_ndim: int, idx: np.ndarray | None) -> np.ndarray:
    """*value*'s rows of the seeds *idx* if it is given per seed (core_ndim + 1 axes), else
    *value* (shared by every seed)."""
    if idx is None or value.ndim == core_ndim:
        return value
    return value[idx]
