"""The measurement models of host.filters.model for N seeds along a leading axis: what the
fusion tracks' twins (host.batch.tracks) update with.

A batch measurement holds its rows for the seeds of one step and gives ``dim``,
``take(k)`` (the seeds *k* of them), ``linearize(x)`` (h and dh/dx at each seed's state
x (n, 6): the EKF's) and ``h(X)`` (each seed's sigma points X (n, s, 6): the UKF's), with
the per-seed model's operations in its order, so each seed's numbers are its own:

* :class:`BatchLinear`: z = H x, H shared (m, 6) or per seed (n, m, 6) (the SINS
  acceleration, a WSN fix with its lag: :func:`position_fixes`);
* :class:`BatchRanges`: ranges to anchors from the lagged positions p_i = c_i (x) I x with
  c_i = (1, -lag_i, lag_i^2/2), each seed its own lags (and its own anchors, a TOA range per
  seed), or their differences to a reference anchor (TDOA: the seeds of one step grouped by
  their anchors and reference, so the reference sits at one place in each seed's rows).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from navtwin.host.filters.model import DIM_X

from .linalg import mv, selection
from .seeds import take


def lag_coefficients(lag: np.ndarray) -> np.ndarray:
    """host.filters.model.lag_coefficients of each lag (...,) -> (..., 3): (1, -lag, lag^2/2)."""
    lag = np.asarray(lag, float)
    return np.stack((np.ones_like(lag), -lag, lag * lag / 2), -1)


class BatchLinear(NamedTuple):
    """host.filters.model.Linear: z = H x, H (m, 6) shared by the seeds or (n, m, 6)."""
    H: np.ndarray

    @property
    def dim(self) -> int:
        return self.H.shape[-2]

    def take(self, k) -> BatchLinear:
        return BatchLinear(take(self.H, 2, k))

    def linearize(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H x (n, m) and H: the products are the KF's H.dot(x) (x's entries, for an H that
        picks them: host.batch.linalg.selection)."""
        return hx(self.H, x), self.H


def hx(H: np.ndarray, x: np.ndarray) -> np.ndarray:
    """H x of each seed's x (n, 6): gemv as for one filter, or the entries an H picks."""
    cols = selection(H)
    return mv(H, x) if cols is None else x.take(cols, 1)


def position_fixes(lag: np.ndarray) -> BatchLinear:
    """host.filters.model.position_fix of each seed's lag: H = c (x) I_2 (n, 2, 6)."""
    c = lag_coefficients(lag)
    H = np.zeros((len(c), 2, DIM_X))
    for k in range(3):
        H[:, 0, 2 * k] = H[:, 1, 2 * k + 1] = c[:, k]
    return BatchLinear(H)


class BatchRanges(NamedTuple):
    """host.filters.model.Ranges of n seeds: the anchors' ``rows`` in the layout, (m,)
    shared or (n, m); the lag coefficients ``c`` (n, m, 3); ``ref``: the reference's place
    in the rows (shared), None for the ranges themselves."""
    layout: object  # host.wsn.AnchorLayout
    rows: np.ndarray
    c: np.ndarray
    ref: int | None = None

    @classmethod
    def of(cls, layout, rows, lags, ref: int | None = None) -> BatchRanges:
        return cls(layout, np.asarray(rows, np.intp), lag_coefficients(lags), ref)

    @property
    def dim(self) -> int:
        m = self.c.shape[1]
        return m if self.ref is None else m - 1

    def take(self, k) -> BatchRanges:
        return self._replace(rows=take(self.rows, 1, k), c=self.c[k])

    def _others(self) -> list[int]:
        return [k for k in range(self.c.shape[1]) if k != self.ref]

    def _differences(self, r: np.ndarray) -> np.ndarray:
        """r itself (..., m), or r_i - r_ref in the rows' order without the reference."""
        if self.ref is None:
            return r
        return r[..., self._others()] - r[..., self.ref:self.ref + 1]

    def h(self, X: np.ndarray) -> np.ndarray:
        """Ranges (n, s, m) or differences (n, s, m - 1) of each seed's points X (n, s, 6)."""
        n, s = X.shape[:2]
        p = np.matmul(self.c[:, None], X.reshape(n, s, 3, 2))  # (n, s, m, 2): C_i X
        rows = self.rows if self.rows.ndim == 1 else self.rows[:, None, :]
        return self._differences(self.layout.ranges(p, rows))

    def linearize(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h(x) (n, dim) and dh/dx (n, dim, 6) at each seed's state x (n, 6), from one
        evaluation of the geometry: d r_i / d x = c_i (x) u_i^T."""
        n, m = self.c.shape[:2]
        r, u = self.layout.geometry(np.matmul(self.c, x.reshape(n, 3, 2)), self.rows)
        J = (self.c[..., None] * u[..., None, :]).reshape(n, m, DIM_X)
        if self.ref is None:
            return r, J
        others = self._others()
        return self._differences(r), J[:, others] - J[:, self.ref:self.ref + 1]
