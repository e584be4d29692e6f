"""Error-state Kalman filter on the strapdown (001 sections 2 and 4.2), closed loop.

State (001 eq. 3, horizontal: the strapdown holds the vehicle on the floor, 000 eq. 5)::

    x = [dp_x, dp_y, dv_x, dv_y, dA_x, dA_y, dA_z, e_1 .. e_m]

dp, dv: the strapdown's position and velocity errors (computed minus true, nav frame); dA:
its attitude error (C_computed = exp(dA x) C_true); e_i: optional random-walk states (001
eq. 17, the NLOS error of anchor i's range). Between updates the nav part of x is zero: each
update's correction is fed back into the strapdown and that part reset (closed loop), so
the predict propagates P alone (eq. 26 maps zero to zero and leaves the e_i unchanged).

Predict over one IMU interval T with the nav-frame specific force f^n (001 eqs. 4-6, 27)::

    F = [[I, T I, -(f^n x)_h T^2/2], [0, I, -(f^n x)_h T], [0, 0, I]]   (+ I on the e_i)
    P = F P F^T + G Q G^T

(f^n x)_h is the two horizontal rows of the skew matrix. W = [gyro angle noise, accel noise]
over T, variances ``gyro_psd`` T and ``accel_psd`` / T (the random walks' densities squared);
with isotropic noise G Q G^T does not depend on C_b^n (its rows are orthonormal):
Q_pp = accel_psd T^3/4, Q_pv = accel_psd T^2/2, Q_vv = accel_psd T, Q_AA = gyro_psd T I,
Q_ee = e_psd T.

Update (001 eqs. 28-30, Joseph form, chi-square gated like host.filters.kf)::

    y = z - H x,  S = H P H^T + R,  K = P H^T S^-1,  x = x + K y,
    P = (I - K H) P (I - K H)^T + K R K^T
"""
from __future__ import annotations

from functools import lru_cache
from itertools import repeat

import numpy as np

from .innovation import Innovation, joseph_correct

NAV = 7  # dp (2), dv (2), dA (3)
P, V, A = slice(0, 2), slice(2, 4), slice(4, 7)


@lru_cache(maxsize=32)
def process_noise(dt: float, gyro_psd: float, accel_psd: float, extra_psd: float, extra: int) -> np.ndarray:
    """G Q G^T over dt (module doc); cached: the IMU period recurs. Read-only."""
    Q = process_noises(np.array([dt]), gyro_psd, accel_psd, extra_psd, extra)[0]
    Q.flags.writeable = False
    return Q


def process_noises(dt: np.ndarray, gyro_psd: float, accel_psd: float, extra_psd: float,
                   extra: int) -> np.ndarray:
    """G Q G^T over each of the intervals dt (k,): (k, n, n) at once (host.batch, where each
    seed has its own interval)."""
    n = NAV + extra
    Q = np.zeros((len(dt), n, n))
    add_process_noises(Q, dt, gyro_psd, accel_psd, extra_psd, extra)
    return Q


def add_process_noises(M: np.ndarray, dt: np.ndarray, gyro_psd: float, accel_psd: float,
                       extra_psd: float, extra: int, powers=None) -> None:
    """M += G Q G^T over each of the intervals dt (k,), M (k, n, n), in place: the nonzero
    entries alone, each the sum M + Q gives (host.batch's F P F^T + Q, with no Q of zeros
    made); *powers*: :func:`interval_powers` of dt, if the caller has them."""
    d2, d3 = interval_powers(dt) if powers is None else powers
    terms = np.column_stack((accel_psd * d3 / 4, accel_psd * d2 / 2, accel_psd * dt,
                             gyro_psd * dt, extra_psd * dt))
    row, col, term = _noise_entries(NAV + extra)
    M[:, row, col] += terms[:, term]


def interval_powers(dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """dt^2 and dt^3 of each interval as Python's float powers (libm's pow), as one interval's
    always were: numpy's power rounds a few percent of them otherwise in the last bit."""
    k = len(dt)
    return (np.fromiter(map(pow, dt.tolist(), repeat(2.0)), float, k),
            np.fromiter(map(pow, dt.tolist(), repeat(3.0)), float, k))


@lru_cache(maxsize=8)
def _noise_entries(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the nonzero entries of G Q G^T (n x n) are (rows, columns), and which of
    add_process_noises' terms (Q_pp, Q_pv, Q_vv, Q_AA, Q_ee) each is."""
    entries = [((i, i), 0) for i in range(2)]
    entries += [((i, i + 2), 1) for i in range(2)] + [((i + 2, i), 1) for i in range(2)]
    entries += [((i, i), 2) for i in range(2, 4)] + [((i, i), 3) for i in range(A.start, A.stop)]
    entries += [((i, i), 4) for i in range(NAV, n)]
    return (np.array([r for (r, _), _ in entries]), np.array([c for (_, c), _ in entries]),
            np.array([k for _, k in entries]))


def transition(F: np.ndarray, dt, fx, fy, fz) -> None:
    """Write the entries of F (001 eqs. 4-6) that depend on the interval dt and the specific
    force (fx, fy, fz) into F, which holds the identity elsewhere: one filter's (n, n) with
    scalars, or N seeds' (N, n, n) with (N,) arrays (host.batch), the same products each."""
    # -(f x) rows x and y: [[0, f_z, -f_y], [-f_z, 0, f_x]]
    h = 0.5 * dt * dt
    F[..., 0, 2] = F[..., 1, 3] = dt
    F[..., 0, 5], F[..., 0, 6], F[..., 1, 4], F[..., 1, 6] = fz * h, -fy * h, -fz * h, fx * h
    F[..., 2, 5], F[..., 2, 6], F[..., 3, 4], F[..., 3, 6] = fz * dt, -fy * dt, -fz * dt, fx * dt


class ClosedLoop:
    """What a closed-loop error-state filter does after its predict: the Joseph update and
    the feedback of its first ``nav`` states into the strapdown (here and host.filters.geodetic)."""

    nav: int

    def update(self, z, H: np.ndarray, R: np.ndarray, gate: float | None = None) -> Innovation:
        """Correct with z = H x + v, v ~ N(0, R) (H: dim(z) x n); the state is unchanged
        when the gate rejects it."""
        z = np.asarray(z, float)
        self.x, self.P, inn = joseph_correct(self.x, self.P, self._I, z - H.dot(self.x), H, R, gate)
        return inn

    def take_nav(self) -> np.ndarray:
        """The nav part of x (to feed back into the strapdown), reset to zero."""
        dx = self.x[:self.nav].copy()
        self.x[:self.nav] = 0.0
        return dx


class ErrorStateFilter(ClosedLoop):
    """x, P of the module doc; ``extra`` random-walk states of density ``extra_psd``."""

    nav = NAV

    def __init__(self, P0: np.ndarray, *, gyro_psd: float, accel_psd: float, extra: int = 0,
                 extra_psd: float = 0.0):
        self.n = n = NAV + extra
        self.x = np.zeros(n)
        self.P = np.array(P0, dtype=float)
        self._noise = (float(gyro_psd), float(accel_psd), float(extra_psd), int(extra))
        self._F = np.eye(n)
        self._I = np.eye(n)

    @property
    def noise(self) -> tuple:
        """process_noise's densities: (gyro_psd, accel_psd, extra_psd, extra)."""
        return self._noise

    def predict(self, dt: float, f_n) -> None:
        """Over one IMU interval dt with the specific force f_n = (f_x, f_y, f_z), nav frame."""
        F = self._F
        transition(F, dt, *f_n)
        self.P = F.dot(self.P).dot(F.T) + process_noise(dt, *self._noise)

