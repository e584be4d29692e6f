"""Inputs along the seed axis: shared by every seed (their core shape, e.g. R (m, m)) or
given per seed (one more leading axis, R (N, m, m)); the rows of a step's seeds as an index.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

#: every row: an index that reads views and writes in place
ALL = slice(None)


def take(value: np.ndarray, core_ndim: int, idx: np.ndarray | None) -> np.ndarray:
    """*value*'s rows of the seeds *idx* if it is given per seed (core_ndim + 1 axes), else
    *value* (shared by every seed)."""
    if idx is None or value.ndim == core_ndim:
        return value
    return value[idx]


def whole(idx: np.ndarray, n: int) -> np.ndarray | slice:
    """The rows *idx* of arrays of n seeds as an index: :data:`ALL` when they are every row
    in order (the common case, where a step then neither gathers nor scatters), else idx."""
    return ALL if len(idx) == n and (idx == _order(n)).all() else idx


@lru_cache(maxsize=8)
def _order(n: int) -> np.ndarray:
    order = np.arange(n)
    order.flags.writeable = False
    return order
