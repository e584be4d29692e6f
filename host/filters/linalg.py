"""Small dense linear algebra for the filters and the WSN solver.

At 1x1 to 6x6 the cost is numpy's per-call overhead, not the arithmetic: ``solve`` calls
LAPACK's gesv directly (what np.linalg.solve and np.linalg.inv call, so the same numbers,
without their wrappers' checks), and ``inverse`` inverts 1x1 and 2x2 in closed form.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=16)
def _identity(m: int) -> np.ndarray:
    eye = np.eye(m)
    eye.flags.writeable = False
    return eye


def _gesv(A: np.ndarray, B: np.ndarray):
    """LAPACK's dgesv, imported on the first solve: scipy.linalg costs a process about 0.3
    CPU-s to import, and most navtwin commands (--help, ctl, emulate) never solve anything."""
    global _gesv
    from scipy.linalg import lapack

    _gesv = lapack.dgesv
    return _gesv(A, B)


def solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A^-1 B (B a vector or a matrix); raises LinAlgError if A is singular."""
    x, info = _gesv(A, B)[2:]
    if info > 0:
        raise np.linalg.LinAlgError("singular matrix")
    return x


def inverse(S: np.ndarray) -> np.ndarray:
    """S^-1; 1x1 and 2x2 (every range and acceleration update) in closed form. Raises
    LinAlgError if S is singular."""
    m = S.shape[0]
    try:
        if m == 1:
            return np.array(((1.0 / S.item(),),))
        if m == 2:
            (a, b), (c, d) = S.tolist()
            det = a * d - b * c
            return np.array(((d / det, -b / det), (-c / det, a / det)))
    except ZeroDivisionError:
        raise np.linalg.LinAlgError("singular matrix") from None
    return solve(S, _identity(m))
