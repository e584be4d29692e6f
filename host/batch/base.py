"""What every batch filter is: x (N, n) and P (N, n, n) of N seeds, the rows of a step's
active seeds, and the gated Joseph update (host.batch.innovation) the KF and the error-state
filter share, as host.filters' KalmanFilter and ClosedLoop share joseph_correct.

A step's ``active`` is None (every seed) or a boolean mask (N,): the step computes on the
active seeds alone (their rows gathered, the results written back), so a seed left out
costs nothing and keeps its x and P.
"""
from __future__ import annotations

import numpy as np

from .innovation import BatchInnovation, joseph_correct
from .linalg import mv
from .seeds import take


class BatchFilter:
    """x (N, n) and P (N, n, n) of N seeds."""

    _I: np.ndarray

    def __init__(self, x, P):
        self.x = np.array(x, dtype=float)
        self.P = np.array(P, dtype=float)
        if self.x.ndim != 2 or self.P.shape != self.x.shape + self.x.shape[-1:]:
            raise ValueError(f"x must be (N, n) and P (N, n, n) (got {self.x.shape} and "
                             f"{self.P.shape}); stack one row per seed")

    def chosen(self, active) -> np.ndarray | None:
        """The indices of the *active* seeds (a boolean mask (N,)), or None for all."""
        if active is None:
            return None
        active = np.asarray(active)
        if active.shape != (len(self.x),) or active.dtype != bool:
            raise ValueError(f"active must be a boolean mask of the {len(self.x)} seeds (got "
                             f"shape {active.shape}, {active.dtype}); pass None for all")
        return np.flatnonzero(active)

    def rows(self, idx: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """x and P of the seeds *idx* (None: all)."""
        return (self.x, self.P) if idx is None else (self.x[idx], self.P[idx])

    def store(self, idx: np.ndarray | None, x: np.ndarray, P: np.ndarray) -> None:
        """The seeds *idx*'s new x and P (None: all seeds')."""
        if idx is None:
            self.x, self.P = x, P
        else:
            self.x[idx], self.P[idx] = x, P

    def given(self, value, core_ndim: int, what: str) -> np.ndarray:
        """*value* as float64, shared (core_ndim axes) or per seed (the N seeds first)."""
        a = np.asarray(value, float)
        if a.ndim not in (core_ndim, core_ndim + 1) or a.ndim > core_ndim and len(a) != len(self.x):
            raise ValueError(f"{what} must have {core_ndim} axes (shared) or {core_ndim + 1} "
                             f"with the {len(self.x)} seeds first (got shape {a.shape})")
        return a

    def correct(self, z, H, R, gate, active) -> BatchInnovation:
        """The *active* seeds corrected with z (N, m) = H x + v, v ~ N(0, R): H (m, n) or
        (N, m, n), R (m, m) or (N, m, m), gate None, one value or (N,)."""
        idx = self.chosen(active)
        z, H, R = self.given(z, 1, "z"), self.given(H, 2, "H"), self.given(R, 2, "R")
        gate = None if gate is None else take(self.given(gate, 0, "gate"), 0, idx)
        H = take(H, 2, idx)
        x, P = self.rows(idx)
        x, P, inn = joseph_correct(x, P, self._I, take(z, 1, idx) - mv(H, x), H, take(R, 2, idx), gate)
        self.store(idx, x, P)
        return BatchInnovation.of_all(len(self.x), idx, inn)
