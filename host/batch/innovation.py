"""The gated Joseph update of N seeds at once (host.filters.innovation, batched).

For each seed (000 eq. 15, 001 eqs. 28-30)::

    y = z - H x,  S = H P H^T + R,  NIS = y^T S^-1 y
    K = P H^T S^-1,  x = x + K y,  P = (I - K H) P (I - K H)^T + K R K^T

A seed whose NIS exceeds the gate (chi-square with dim(z) degrees of freedom, e.g.
``host.wsn.chi2_gate``) is rejected and keeps its x and P: the gain and the Joseph products
are computed for the accepted seeds alone, each with the per-filter products in the same
order (host.batch.linalg), so each seed's x and P are the per-filter update's. A shared H
that picks states (host.batch.linalg.selection: the Motion products') has P H^T and H P H^T
taken, not multiplied: the same numbers. (K H is multiplied: filling I - K H column by
column costs more than the product.)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .linalg import T, dot, inverse, mv, selection, vm
from .seeds import take


class BatchInnovation(NamedTuple):
    """One update's innovations, per seed; a seed left out of the step has NaN in y, S and
    nis and is not accepted."""
    y: np.ndarray  # (N, m): z - h(x_prior)
    S: np.ndarray  # (N, m, m): its covariance
    nis: np.ndarray  # (N,): y^T S^-1 y
    accepted: np.ndarray  # (N,) bool: within the gate (and in the step)

    @classmethod
    def of_all(cls, n: int, idx: np.ndarray | None, inn: BatchInnovation) -> BatchInnovation:
        """*inn* of the seeds *idx* (None: all n) spread over the n seeds."""
        if idx is None:
            return inn
        m = inn.y.shape[-1]
        y, S, nis = np.full((n, m), np.nan), np.full((n, m, m), np.nan), np.full(n, np.nan)
        accepted = np.zeros(n, bool)
        y[idx], S[idx], nis[idx], accepted[idx] = inn
        return cls(y, S, nis, accepted)


def projected(P: np.ndarray, H: np.ndarray, R: np.ndarray, cols) -> tuple[np.ndarray, np.ndarray]:
    """P H^T (N, n, m) and S = H P H^T + R of each seed's P (N, n, n); *cols*: the entries a
    shared H picks (host.batch.linalg.selection), taken, or None to multiply."""
    if cols is None:
        PHT = np.matmul(P, T(H))
        return PHT, np.matmul(H, PHT) + R
    PHT = P.take(cols, 2)  # C-ordered (N, n, m), as the product is
    return PHT, PHT.take(cols, 1) + R


def joseph_correct(x: np.ndarray, P: np.ndarray, I: np.ndarray, y: np.ndarray, H: np.ndarray,
                   R: np.ndarray, gate) -> tuple[np.ndarray, np.ndarray, BatchInnovation]:
    """The update of innovations y (N, m) for x (N, n), P (N, n, n); H (m, n) or (N, m, n), R
    (m, m) or (N, m, m), gate None, one value or (N,); I the identity of P's size. Returns
    the new x and P (new arrays if any seed changed) and the innovations."""
    cols = selection(H)
    PHT, S = projected(P, H, R, cols)
    SI = inverse(S)

    def correct(rows, a):
        K = np.matmul(rows(PHT), rows(SI))
        I_KH = I - np.matmul(K, take(H, 2, a))
        return rows(x) + mv(K, rows(y)), np.matmul(np.matmul(I_KH, rows(P)), T(I_KH)) \
            + np.matmul(np.matmul(K, take(R, 2, a)), T(K))

    return gated(x, P, y, S, SI, gate, correct)


def gated(x: np.ndarray, P: np.ndarray, y: np.ndarray, S: np.ndarray, SI: np.ndarray, gate,
          correct) -> tuple[np.ndarray, np.ndarray, BatchInnovation]:
    """An update's gate and scatter: NIS = y^T S^-1 y per seed; the seeds within *gate* (None:
    all) take ``correct(rows, a)``'s new x and P of their rows (*rows* picks them from an
    array, *a* their indices, None for every seed), the others keep theirs (new arrays if
    any seed changed); with the innovations."""
    nis = dot(vm(y, SI), y)
    accepted = np.ones(len(nis), bool) if gate is None else nis <= gate
    a = None if accepted.all() else np.flatnonzero(accepted)
    if a is None or a.size:
        def rows(v):
            return v if a is None else v[a]
        xa, Pa = correct(rows, a)
        if a is None:
            x, P = xa, Pa
        else:
            x, P = x.copy(), P.copy()
            x[a], P[a] = xa, Pa
    return x, P, BatchInnovation(y, S, nis, accepted)
