"""003's error-state Kalman filter on the geodetic strapdown (003 sect. 3, eqs. 13-16, 21-24),
closed loop.

State (003 eq. 16, and eq. 22's magnetometer heading error as a 16th)::

    x = [dV_E, dV_N, dV_U, phi_E, phi_N, phi_U, dL, dlambda, dh,
         nabla_bx, nabla_by, nabla_bz, eps_bx, eps_by, eps_bz, dpsi_mag]

dV: velocity error (ENU, m/s); phi: misalignment (rad, ENU: C_computed = (I - phi x) C_true);
dL, dlambda (rad), dh (m): position error; nabla: the accelerometer bias left in the samples
(m/s^2, body); eps: the gyro drift left (rad/s, body); dpsi_mag: the magnetometer heading's
error (rad, its yaw minus the true yaw). All computed minus true.

F_SINS (eq. 13; 003 says only "determined by the SINS error equation"): the phi-angle error
model of PSINS's ``etm`` (Yan Gongmin, *Strapdown Inertial Navigation Algorithm and Integrated
Navigation Principles*, eqs. 4.2.x; Titterton & Weston eqs. 12.6-12.15 in their psi/phi form),
with R_Mh = R_M + h, R_Nh = R_N + h, w_in = w_ie + w_en, v = v^n, f = f^n, C = C_b^n::

    phi'  = -(w_in x) phi + M_av dV + M_ap dp - C eps
    dV'   = (f x) phi + ((v x) M_av - ((2 w_ie + w_en) x)) dV + (v x)(2 M_1 + M_2) dp + C nabla
    dp'   = M_pv dV + M_pp dp
    nabla' = w_a,  eps' = w_g,  dpsi_mag' = w_m              (random walks)

    M_av = [[0, -1/R_Mh, 0], [1/R_Nh, 0, 0], [tan L/R_Nh, 0, 0]]
    M_1  = [[0, 0, 0], [-W sin L, 0, 0], [W cos L, 0, 0]]
    M_2  = [[0, 0, v_N/R_Mh^2], [0, 0, -v_E/R_Nh^2], [v_E sec^2 L/R_Nh, 0, -v_E tan L/R_Nh^2]]
    M_ap = M_1 + M_2
    M_pv = [[0, 1/R_Mh, 0], [sec L/R_Nh, 0, 0], [0, 0, 1]]
    M_pp = [[0, 0, -v_N/R_Mh^2], [v_E sec L tan L/R_Nh, 0, -v_E sec L/R_Nh^2], [0, 0, 0]]

PSINS's gravity row (dg/dL, dg/dh in M_vp's third row) is left out: the host's gravity is a
constant (host.geodetic), so the strapdown's error has none. The radii's change with L
(dR/dL, a 1e-9 relative term) is left out as in PSINS. tests/host/test_geodetic.py checks F
against a numerical Jacobian of one strapdown step.

Predict over one IMU interval T, discretised to first order (the largest product in
(F T)^2, g / R T^2, is 1.5e-10 at 100 Hz)::

    Phi = I + F T,   P = Phi P Phi^T + Q_c T
    Q_c = diag(accel_psd I3, gyro_psd I3, 0, accel_bias_psd I3, gyro_drift_psd I3, mag_psd)

with the noise of the white sensor errors isotropic (so C Q C^T = Q). Between updates the
first 15 states of x are zero (each update's correction is fed back into the strapdown and
those states reset: closed loop, as host.filters.errorstate); the 16th's row of F is zero,
so the predict moves P alone.

Update (003 eqs. 18, 23; Joseph form, chi-square gated, host.filters.innovation)::

    y = z - H x,  S = H P H^T + R,  K = P H^T S^-1,  x = x + K y,
    P = (I - K H) P (I - K H)^T + K R K^T
"""
from __future__ import annotations

import math

import numpy as np

from navtwin.common.earth import EARTH_RATE

from .errorstate import ClosedLoop

N = 16
NAV = 15  # fed back into the strapdown
V, PHI, POS, ACCEL_BIAS, GYRO_DRIFT, MAG = (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12),
                                             slice(12, 15), 15)


def _skew(a) -> list[list[float]]:
    x, y, z = a
    return [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]


def error_model(lat: float, h_radii: tuple[float, float], v, f_n, C) -> np.ndarray:
    """F_SINS (15 x 15, module docstring) at latitude ``lat`` (rad) with (R_Mh, R_Nh)
    ``h_radii`` (m), velocity ``v`` and specific force ``f_n`` (ENU), C = C_b^n (3 rows)."""
    rm, rn = h_radii
    ve, vn, _ = v
    sl, cl = math.sin(lat), math.cos(lat)
    tl, secl = sl / cl, 1.0 / cl
    w_ie = (0.0, EARTH_RATE * cl, EARTH_RATE * sl)
    w_en = (-vn / rm, ve / rn, ve * tl / rn)
    m_av = np.array([[0.0, -1.0 / rm, 0.0], [1.0 / rn, 0.0, 0.0], [tl / rn, 0.0, 0.0]])
    m_1 = np.array([[0.0, 0.0, 0.0], [-w_ie[2], 0.0, 0.0], [w_ie[1], 0.0, 0.0]])
    m_2 = np.array([[0.0, 0.0, vn / rm**2], [0.0, 0.0, -ve / rn**2],
                    [ve * secl * secl / rn, 0.0, -ve * tl / rn**2]])
    av = np.array(_skew(v))
    F = np.zeros((NAV, NAV))
    F[PHI, PHI] = _skew([-(a + b) for a, b in zip(w_ie, w_en)])
    F[PHI, V] = m_av
    F[PHI, POS] = m_1 + m_2
    F[PHI, GYRO_DRIFT] = -np.asarray(C)
    F[V, PHI] = _skew(f_n)
    F[V, V] = av @ m_av - np.array(_skew([2.0 * a + b for a, b in zip(w_ie, w_en)]))
    F[V, POS] = av @ (2.0 * m_1 + m_2)
    F[V, ACCEL_BIAS] = C
    F[POS, V] = [[0.0, 1.0 / rm, 0.0], [secl / rn, 0.0, 0.0], [0.0, 0.0, 1.0]]
    F[POS, POS] = [[0.0, 0.0, -vn / rm**2], [ve * secl * tl / rn, 0.0, -ve * secl / rn**2],
                   [0.0, 0.0, 0.0]]
    return F


class GeodeticErrorFilter(ClosedLoop):
    """x, P of the module doc; ``psd``: the 16 white-noise densities of Q_c's diagonal."""

    nav = NAV

    def __init__(self, P0: np.ndarray, psd) -> None:
        self.x = np.zeros(N)
        self.P = np.array(P0, dtype=float)
        self._qc = np.asarray(psd, float)
        self._I = np.eye(N)
        self._Phi = np.eye(N)

    def predict(self, dt: float, F: np.ndarray) -> None:
        """Over one IMU interval dt with F_SINS (15 x 15) of its start."""
        Phi = self._Phi
        Phi[:NAV, :NAV] = F * dt
        Phi[:NAV, :NAV] += self._I[:NAV, :NAV]
        P = Phi.dot(self.P).dot(Phi.T)
        P[np.diag_indices(N)] += self._qc * dt
        self.P = P

