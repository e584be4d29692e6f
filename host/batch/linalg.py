"""Stacked small linear algebra along the seed axis, the same numbers as host.filters.linalg.

``np.matmul`` on stacked operands calls BLAS once per seed with that seed's operands (gemm
for matrix x matrix, gemv for a matrix times an (n, 1) column, dot for a row times a
column): the routines ``ndarray.dot`` calls for one filter. ``x @ A.T`` on an (N, n) stack
would be one gemm whose rounding differs from gemv's in the last bit, so vectors go through
:func:`mv` as columns. The inverse is host.filters.linalg.inverse's: 1x1 and 2x2 in closed
form (the same float operations elementwise), larger ones by the same LAPACK gesv seed by
seed.
"""
from __future__ import annotations

import numpy as np

from navtwin.host.filters.linalg import inverse as one_inverse


def mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x per seed: A (N, m, n) or (m, n), x (N, n) -> (N, m); gemv as for one filter."""
    return np.matmul(A, x[..., None])[..., 0]


def vm(x: np.ndarray, A: np.ndarray) -> np.ndarray:
    """x^T A per seed: x (N, m), A (N, m, n) -> (N, n); gemv as ``x.dot(A)``."""
    return np.matmul(x[:, None, :], A)[:, 0, :]


def dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x . y per seed: (N, n), (N, n) -> (N,); BLAS dot as ``x.dot(y)``."""
    return np.matmul(x[:, None, :], y[:, :, None])[:, 0, 0]


def T(A: np.ndarray) -> np.ndarray:
    """The transpose of each seed's matrix (a view, as ``A.T`` is)."""
    return np.swapaxes(A, -1, -2)


def inverse(S: np.ndarray) -> np.ndarray:
    """S^-1 of each seed's S (N, m, m); LinAlgError naming the seeds whose S is singular."""
    m = S.shape[-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        if m == 1:
            SI = 1.0 / S
            singular = S[:, 0, 0] == 0.0
        elif m == 2:
            a, b, c, d = S[:, 0, 0], S[:, 0, 1], S[:, 1, 0], S[:, 1, 1]
            det = a * d - b * c
            SI = np.stack((np.stack((d / det, -b / det), -1), np.stack((-c / det, a / det), -1)), -2)
            singular = det == 0.0
        else:
            SI, singular = _solved(S)
    if singular.any():
        raise np.linalg.LinAlgError(f"singular innovation covariance at seeds "
                                    f"{np.flatnonzero(singular).tolist()}; leave them out "
                                    "(active) and re-initialise them")
    return SI


def _solved(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3x3 and larger (a TDOA cycle, several ranges at once: one update a cycle) seed by seed
    with the per-filter gesv: numpy's batched solve is another LAPACK build, whose pivoted
    LU rounds differently from 6x6 on, and gesv's result is column-major, which decides the
    gemv that later products of S^-1 take (so each seed's slice is column-major here too)."""
    SI = np.zeros(S.shape)
    singular = np.zeros(len(S), bool)
    for k, s in enumerate(S):
        try:
            SI[k] = one_inverse(s).T
        except np.linalg.LinAlgError:
            singular[k] = True
    return T(SI), singular
