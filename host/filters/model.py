"""Motion and measurement models shared by the KF, EKF and UKF (000 section 4).

State (000 sect. 4.1), area frame, SI units::

    x = [x, y, vx, vy, ax, ay]^T

Motion, constant acceleration driven by white jerk (000 eq. 14, x_{k+1} = f_k x_k + w_k)::

    F(dt) = [[I, dt I, dt^2/2 I],      Q(dt) = q_j [[dt^5/20, dt^4/8, dt^3/6],
             [0,    I,     dt I],                   [dt^4/8,  dt^3/3, dt^2/2],   (x) I_2
             [0,    0,        I]]                   [dt^3/6,  dt^2/2, dt    ]]

``q_j`` is the jerk power spectral density per axis (m^2/s^5). Q is the exact
discretisation, so predicting by dt1 then dt2 equals predicting by dt1 + dt2.

Measurements (000 eq. 15, z_k = h_k(x_k) + v_k, v_k ~ N(0, R)):

=================  ===============================================  ==========================
class              h(x)                                             used for
=================  ===============================================  ==========================
Linear(H)          H x                                              SINS acceleration
                                                                    (H = [0 0 I]); WSN fix
                                                                    (H = lag_matrix(lag))
Ranges             r_i(p_i), p_i = p - lag_i v + lag_i^2/2 a        TOA ranges (000 eqs. 10-11)
Ranges(reference)  r_i(p_i) - r_ref(p_ref), i != ref                TDOA (000 eqs. 12-13)
=================  ===============================================  ==========================

A measurement taken ``lag`` seconds before the filter's time is predicted by running the
same constant-acceleration model backwards (p - lag v + lag^2/2 a); the process noise
over the lag (tens of milliseconds) is neglected. Every ``h`` works on one state (6,) and
on a stack of sigma points (N, 6); ``linearize(x)`` gives h(x) and dh/dx at one state (the
EKF's), ``jacobian(x)`` the latter alone.
"""
from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # a type only: host.wsn imports this package's linalg
    from navtwin.host.wsn import AnchorLayout

DIM_X = 6
_I2 = np.eye(2)


def _kron_basis(blocks: list[list[list[float]]]) -> np.ndarray:
    """Rows = the 3x3 blocks (x) I_2, flattened: F and Q are a small matmul away."""
    return np.stack([np.kron(np.array(b, float), _I2).ravel() for b in blocks])


# F(dt) = [1, dt, dt^2/2] @ _F_BASIS; Q(dt) = q [dt, dt^2/2, dt^3/3, dt^3/6, dt^4/8, dt^5/20] @ _Q_BASIS
_F_BASIS = _kron_basis([[[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                        [[0, 1, 0], [0, 0, 1], [0, 0, 0]],
                        [[0, 0, 1], [0, 0, 0], [0, 0, 0]]])
_Q_BASIS = _kron_basis([[[0, 0, 0], [0, 0, 0], [0, 0, 1]],
                        [[0, 0, 0], [0, 0, 1], [0, 1, 0]],
                        [[0, 0, 0], [0, 1, 0], [0, 0, 0]],
                        [[0, 0, 1], [0, 0, 0], [1, 0, 0]],
                        [[0, 1, 0], [1, 0, 0], [0, 0, 0]],
                        [[1, 0, 0], [0, 0, 0], [0, 0, 0]]])


class ConstantAcceleration:
    """F(dt) and Q(dt) of the white-jerk constant-acceleration model (000 eq. 14)."""

    def __init__(self, jerk_psd: float):
        self.jerk_psd = float(jerk_psd)
        # F and Q by dt: the IMU period recurs (a few values, as the host clock's rate
        # estimate steps), and the filters sharing a model share each dt
        self._transition = lru_cache(maxsize=32)(self._build)

    # ndarray.dot rather than @ here and in the filters: the same BLAS call, a third of
    # the overhead on these 6x6 operands (navtwin bench host-filters)
    def F(self, dt: float) -> np.ndarray:
        return np.array((1.0, dt, dt * dt / 2)).dot(_F_BASIS).reshape(DIM_X, DIM_X)

    def Q(self, dt: float) -> np.ndarray:
        d2 = dt * dt
        d3 = d2 * dt
        powers = np.array((dt, d2 / 2, d3 / 3, d3 / 6, d2 * d2 / 8, d3 * d2 / 20))
        return (self.jerk_psd * powers).dot(_Q_BASIS).reshape(DIM_X, DIM_X)

    def many(self, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F and Q (n, 6, 6) for n values of dt at once (host.batch): the same numbers as
        :meth:`F` and :meth:`Q` of each, since every entry of either is one term of its sum
        (the blocks of the bases do not overlap), whatever order a product sums in."""
        dt = np.asarray(dt, float)
        d2 = dt * dt
        d3 = d2 * dt
        F = np.column_stack((np.ones_like(dt), dt, d2 / 2)).dot(_F_BASIS)
        powers = np.column_stack((dt, d2 / 2, d3 / 3, d3 / 6, d2 * d2 / 8, d3 * d2 / 20))
        Q = (self.jerk_psd * powers).dot(_Q_BASIS)
        return F.reshape(-1, DIM_X, DIM_X), Q.reshape(-1, DIM_X, DIM_X)

    def _build(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        F, Q = self.F(dt), self.Q(dt)
        F.flags.writeable = Q.flags.writeable = False  # cached
        return F, Q

    def propagate(self, x: np.ndarray, P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Linear prediction: F x, F P F^T + Q."""
        F, Q = self._transition(dt)
        return F.dot(x), F.dot(P).dot(F.T) + Q


def lag_coefficients(lag: float) -> tuple[float, float, float]:
    """c = (1, -lag, lag^2/2): the position ``lag`` seconds earlier is c_0 p + c_1 v + c_2 a."""
    return (1.0, -lag, lag * lag / 2)


def lag_matrix(lag: float) -> np.ndarray:
    """C with C x = the position ``lag`` seconds earlier: c (x) I = [I, -lag I, lag^2/2 I] (2x6)."""
    return np.hstack([c * _I2 for c in lag_coefficients(lag)])


class Linear:
    """z = H x."""

    def __init__(self, H: np.ndarray):
        self.H = np.asarray(H, float)
        self.dim = self.H.shape[0]

    def h(self, x: np.ndarray) -> np.ndarray:
        return x.dot(self.H.T)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.H

    def linearize(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h(x) and dh/dx(x)."""
        return self.h(x), self.H


#: The SINS nav-frame horizontal acceleration measures (ax, ay) directly.
ACCELERATION = Linear(np.hstack([np.zeros((2, 4)), _I2]))


def position_fix(lag: float = 0.0) -> Linear:
    """A WSN position fix taken ``lag`` seconds before the filter's time."""
    return Linear(lag_matrix(lag))


class Ranges:
    """Ranges to ``anchors`` (000 eqs. 10-11), or with ``reference`` their differences
    r_i - r_ref in the order of ``anchors`` without the reference (000 eqs. 12-13).

    ``lags[i]``: seconds between range i's exchange and the filter's time (>= 0).
    """

    def __init__(self, layout: AnchorLayout, anchors: Sequence[int],
                 lags: Sequence[float] | None = None, reference: int | None = None):
        self.layout = layout
        self.anchors = tuple(anchors)
        self.idx = layout.index(self.anchors)
        m = len(self.anchors)
        lags = [0.0] * m if lags is None else lags
        self.lags = tuple(lags)  # read by host.batch.model, which stacks the seeds' lags
        self.reference = reference
        self._c = np.array([lag_coefficients(lag) for lag in lags])  # (m, 3): C_i = c_i (x) I
        if reference is None:
            self._ref, self._others = None, None
            self.dim = m
        else:
            self._ref = self.anchors.index(reference)
            self._others = np.array([k for k in range(m) if k != self._ref], dtype=np.intp)
            self.dim = m - 1

    def h(self, x: np.ndarray) -> np.ndarray:
        p = self._c @ x.reshape(*x.shape[:-1], 3, 2)  # lagged positions C_i x, (..., m, 2)
        r = self.layout.ranges(p, self.idx)
        return r if self._ref is None else r[..., self._others] - r[..., self._ref:self._ref + 1]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.linearize(x)[1]

    def linearize(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """h(x) and dh/dx(x) of one state, from one evaluation of the geometry."""
        r, u = self.layout.geometry(self._c.dot(x.reshape(3, 2)), self.idx)
        # d r_i / d x = u_i^T C_i = c_i (x) u_i^T
        J = (self._c[:, :, None] * u[:, None, :]).reshape(len(u), DIM_X)
        if self._ref is None:
            return r, J
        return r[self._others] - r[self._ref], J[self._others] - J[self._ref]
