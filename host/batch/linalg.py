"""Stacked small linear algebra along the seed axis, the same numbers as host.filters.linalg.

``np.matmul`` on stacked operands calls BLAS once per seed with that seed's operands (gemm
for matrix x matrix, gemv for a matrix times an (n, 1) column, dot for a row times a
column): the routines ``ndarray.dot`` calls for one filter. ``x @ A.T`` on an (N, n) stack
would be one gemm whose rounding differs from gemv's in the last bit, so vectors go through
:func:`mv` as columns. The inverse is host.filters.linalg.inverse's: 1x1 and 2x2 in closed
form (the same float operations elementwise), larger ones by LAPACK's gesv
(:func:`solve_each`).

A shared H whose rows are rows of the identity (a Motion product's: it measures some of the
states) picks entries: in H x, P H^T and H P H^T every entry is one term 1 * a plus zeros,
exact whatever order a product sums in, so taking the entries (:func:`selection`) gives the
products' numbers without their BLAS calls (for finite operands, as every covariance here is).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from navtwin.host.filters.linalg import solve as one_solve

#: The largest systems numpy's stacked solve (its own LAPACK build's gesv) gives the per-filter
#: solve's (scipy's gesv) numbers for, bit for bit: every one of 20 000 random SPD systems of
#: each size 2 to 5 alike, about one in ten 6x6 and one in three 7x7 not (numpy 2.4.6, scipy
#: 1.17.1; tests/host/test_batch.py checks the builds installed). Larger ones go seed by seed.
STACKED_UP_TO = 5


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
    return A.swapaxes(-1, -2)


def selection(H: np.ndarray) -> np.ndarray | None:
    """The columns a shared H (m, n) picks, row by row, if each of its rows is a row of the
    identity (module doc); None otherwise, or for an H per seed (N, m, n)."""
    return _picks(H.shape, H.dtype.str, H.tobytes()) if H.ndim == 2 else None


@lru_cache(maxsize=16)
def _picks(shape: tuple[int, int], dtype: str, data: bytes) -> np.ndarray | None:
    H = np.frombuffer(data, dtype).reshape(shape)
    ones = H == 1.0
    if not ((ones | (H == 0.0)).all() and (ones.sum(1) == 1).all()):
        return None
    cols = ones.argmax(1)
    cols.flags.writeable = False  # cached
    return cols


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
            SI = np.empty(S.shape)
            SI[:, 0, 0], SI[:, 0, 1], SI[:, 1, 0], SI[:, 1, 1] = d / det, -b / det, -c / det, a / det
            singular = det == 0.0
        else:
            SI, singular = _solved(S)
    if singular.any():
        raise np.linalg.LinAlgError(f"singular innovation covariance at seeds "
                                    f"{np.flatnonzero(singular).tolist()}; leave them out "
                                    "(active) and re-initialise them")
    return SI


def _solved(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3x3 and larger (a TDOA cycle, several ranges at once: one update a cycle): gesv's
    result is column-major, which decides the gemv that later products of S^-1 take, so
    each seed's slice is column-major here too."""
    SI, singular = solve_each(S, np.broadcast_to(np.eye(S.shape[-1]), S.shape))
    return T(np.ascontiguousarray(T(SI))), singular


def solve_each(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """host.filters.linalg.solve of each seed's A (N, m, m) and B (N, m) or (N, m, k): the
    numbers its gesv gives (in one stacked call up to :data:`STACKED_UP_TO`, else seed by
    seed), and which seeds' A is singular (their rows of the answer: zeros)."""
    if A.shape[-1] <= STACKED_UP_TO:
        try:
            if B.ndim == 2:
                return np.linalg.solve(A, B[..., None])[..., 0], np.zeros(len(A), bool)
            return np.linalg.solve(A, B), np.zeros(len(A), bool)
        except np.linalg.LinAlgError:
            pass  # some seed's A is singular: seed by seed, to tell which
    X = np.zeros(B.shape)
    singular = np.zeros(len(A), bool)
    for k in range(len(A)):
        try:
            X[k] = one_solve(A[k], B[k])
        except np.linalg.LinAlgError:
            singular[k] = True
    return X, singular
