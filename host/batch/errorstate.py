"""The closed-loop error-state filter of host.filters.errorstate for N seeds (001 sections 2
and 4.2), each with its own specific force.

Predict over one IMU interval T with seed s's nav-frame specific force f^n_s (001 eqs. 4-6,
27)::

    F_s = [[I, T I, -(f^n_s x)_h T^2/2], [0, I, -(f^n_s x)_h T], [0, 0, I]]   (+ I on the e_i)
    P_s = F_s P_s F_s^T + G Q G^T

G Q G^T is ``host.filters.errorstate.process_noise`` of each seed's T (``add_process_noises``:
the seeds' intervals at once, added to F P F^T's nonzero entries alone; the noise densities
are the filter's). Update: the gated
Joseph form (001 eqs. 28-30) of host.batch.innovation; ``take_nav`` resets the nav part
after its feedback (closed loop). Each seed's P equals ErrorStateFilter's stepped alone,
bit for bit (tests/host/test_batch.py).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from navtwin.host.filters.errorstate import (NAV, add_process_noises, interval_powers, process_noise,
                                             transition)

from .base import BatchFilter
from .innovation import BatchInnovation
from .linalg import T
from .seeds import take


def propagate(P: np.ndarray, dt, f_n: np.ndarray, noise: tuple) -> np.ndarray:
    """F P F^T + G Q G^T (module doc) of the seeds' P (k, n, n), over dt (one value, or (k,)
    per seed) with each seed's specific force f_n (k, 3) (or one (3,)); *noise* is
    process_noise's (gyro_psd, accel_psd, extra_psd, extra)."""
    F = np.empty(P.shape)
    F[:] = _eye(P.shape[-1])
    transition(F, dt, *f_n.T)
    M = np.matmul(np.matmul(F, P), T(F))
    if np.ndim(dt) == 0:
        M += process_noise(float(dt), *noise)
    else:
        add_process_noises(M, dt, *noise, _powers(dt))
    return M


class _LastPowers:
    """interval_powers of the last intervals asked for: a batch's error-state tracks predict
    over the same intervals (each seed's IMU step) one after another, so two of three find
    theirs here rather than take Python's powers of every seed's again."""

    def __init__(self) -> None:
        self._key, self._powers = None, None

    def __call__(self, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = dt.tobytes()
        if key != self._key:
            self._key, self._powers = key, interval_powers(dt)
            for a in self._powers:
                a.flags.writeable = False  # shared
        return self._powers


_powers = _LastPowers()


@lru_cache(maxsize=8)
def _eye(n: int) -> np.ndarray:
    """I (n, n), read-only: what F is outside transition's entries."""
    I = np.eye(n)
    I.flags.writeable = False
    return I


class BatchErrorStateFilter(BatchFilter):
    """x (N, n) = 0 and P (N, n, n) = *P0* of N seeds; ``extra`` random-walk states of
    density ``extra_psd`` after the nav part."""

    nav = NAV

    def __init__(self, P0, *, gyro_psd: float, accel_psd: float, extra: int = 0,
                 extra_psd: float = 0.0):
        P0 = np.asarray(P0, float)
        super().__init__(np.zeros(P0.shape[:2]), P0)
        self.n = n = NAV + extra
        if self.x.shape[1] != n:
            raise ValueError(f"P0 must be (N, {n}, {n}) for {extra} extra states (got "
                             f"{P0.shape}); give one row per seed")
        self._noise = (float(gyro_psd), float(accel_psd), float(extra_psd), int(extra))
        self._I = np.eye(n)

    def predict(self, dt, f_n, active=None) -> None:
        """Over dt (one value, or (N,) per seed) with each seed's specific force f_n (N, 3)
        (or one (3,) for all), nav frame, for the *active* seeds (None: all)."""
        idx = self.chosen(active)
        dt = take(self.given(dt, 0, "dt"), 0, idx)
        x, P = self.rows(idx)
        self.store(idx, x, propagate(P, dt, take(self.given(f_n, 1, "f_n"), 1, idx), self._noise))

    def update(self, z, H, R, gate=None, active=None) -> BatchInnovation:
        """Correct the *active* seeds with z (N, m) = H x + v, v ~ N(0, R) (H (m, n) or
        (N, m, n), R (m, m) or (N, m, m)); a seed whose NIS exceeds *gate* is unchanged."""
        return self.correct(z, H, R, gate, active)

    def take_nav(self, active=None) -> np.ndarray:
        """The nav part of x (N, 7) of the *active* seeds (to feed back into their
        strapdowns), reset to zero in x; zero rows for the others (theirs stays in x)."""
        idx = self.chosen(active)
        rows = slice(None) if idx is None else idx
        dx = np.zeros((len(self.x), self.nav))
        dx[rows] = self.x[rows, :self.nav]
        self.x[rows, :self.nav] = 0.0
        return dx
