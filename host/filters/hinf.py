"""004's H-infinity filter (004 section 2): its gain from the LMI of Theorem 2.3.

The error system (004 eqs. 2.1-2.8) on the relative errors X = [ex, ey, evx, evy] of the
INS position and velocity, sampled every T with a random sampling-time error dt beta_k
(beta_k zero-mean, unit variance)::

    X_{k+1} = (A + E beta_k) X_k + B1 s_k              (2.4, 2.8)
    Y_k     = C X_k + D1 s_k,   Z_k = L X_k            (2.5, 2.6, 2.8)

    A = [[I, T I], [0, I]],  E = [[0, dt I], [0, 0]]   (2.3)
    B1 = [B 0],  D1 = [0 D],  s_k = [w_k; v_k],  C = L = I4

Y = INS - WSN position and velocity (2.5). 004 takes B = D = I; here B = diag(process) and
D = diag(measurement), the per-axis scales of the INS drift and the WSN noise, so the gain
weighs the two (a deviation; B = D = I is process = measurement = 1).

The filter (2.9) X^_{k+1} = Af X^_k + Bf Y_k leaves the error e = X - X^ (2.10, 2.11)::

    e_{k+1} = (A~ + E beta_k) e_k + B~ s_k,   A~ = A - Bf C,  B~ = B1 - Bf D1

and the gain makes J = E sum(|L e_k|^2 - gamma^2 |s_k|^2) < 0 (2.12) with (2.11) mean-square
stable when there are P = P' > 0 and Q (= P Bf) with (2.15), g = gamma^2::

    [[-P,       0,     A'P-C'Q',  A'P-C'Q',  L',  E'P],
     [ 0,     -g I,   B1'P-D1'Q',    0,      0,    0 ],
     [PA-QC, PB1-QD1,    -P,         0,      0,    0 ],
     [PA-QC,    0,        0,        -P,      0,    0 ],   < 0        (2.15)
     [ L,       0,        0,         0,     -I,    0 ],
     [ PE,      0,        0,         0,      0,   -P ]]

:func:`solve_gain` minimises g subject to (2.15) and P > 0 (2.22, 2.23) with cvxpy and
Clarabel and returns Bf = P^-1 Q, Af = A - Bf C (2.24; 2.25 as E beta_k has mean 0).

**(2.15) as written is conservative.** The Schur complement of its last four block rows is
-P + 2 A~'P A~ + L'L + E'PE + ... : A~'P A~ twice, once from the third block row and once
from the fourth, where (2.16) has it once. The slip is in (2.19), whose Delta already holds
A~'P A~ when the third Schur complement adds it again. (2.15) implies the exact bounded-real
inequality (2.16), so its gamma is an upper bound on the true worst-case gain
(tests/host/test_hinf.py confirms it on the unit circle and by Monte Carlo), only not the
least one: with B = D = I, T = 1 s, dt = 1.2 ms (004's E) the exact inequality reaches
gamma = 1.8459, (2.15) 1.8496. We solve (2.15) as 004 states it.

**Strictness and scale.** The strict inequalities are <= -eps I and P >= eps I with
``EPS`` = 1e-6. The weights B and D are divided by their largest so that eps is relative to
weights of 1: s_k scales out of (2.11) (gamma scales with the weights, P, Q and Bf do not),
so gamma is multiplied back.

**What we get against 004 eq. 5.1** (B = D = I, dt = 1.2 ms): with T = 1 s gamma = 1.8496,
Bf ~ [[1.072, 0.864], [0.107, 0.799]] (x) I2, spectral radius of A~ 0.128; with T = 0.2 s
gamma = 1.4897, Bf ~ [[0.973, 0.232], [0.045, 0.948]] (x) I2. 004 prints Bf = A with
T = 0.2 (its text says T = 1 s), so A~ = Af ~ 1e-11: the dead-beat gain, whose worst-case
gain sqrt(1 + |A|^2) = 1.4898 is within 1e-4 of our optimum; the optimum is flat around it,
so the solver's Bf is one of many near-optimal gains close to A. 004's gamma = 4.0055 we do
not reproduce from what it states (the dead-beat gain's gamma is 1.49 at T = 0.2 s, 1.90 at
T = 1 s).

Solved once at start-up: :attr:`HinfGain.seconds` holds the time, 20-30 ms with Clarabel
(28 x 28 LMI, 15 unknowns), 0.7 s for the first solve of a process, which imports cvxpy.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from navtwin.common.extras import require

#: The margin that makes (2.15) and P > 0 strict: <= -EPS I, >= EPS I (weights normalised to 1).
EPS = 1e-6
#: Who needs cvxpy and Clarabel, in the line that says how to install them.
WHO = "hinf"


class HinfError(ValueError):
    """The LMI (2.15) has no solution the solver can certify."""


@dataclass(frozen=True)
class ErrorSystem:
    """The matrices of (2.8): A, E (2.3), B1 = [B 0], D1 = [0 D], C = L = I4."""
    A: np.ndarray
    E: np.ndarray
    B1: np.ndarray
    D1: np.ndarray
    C: np.ndarray
    L: np.ndarray

    @classmethod
    def build(cls, T: float, dt: float, process, measurement) -> ErrorSystem:
        """T the sample time, dt the sampling-time error's scale (E's entry), *process* and
        *measurement* the diagonals of B and D (4 each, or one number for all four)."""
        I2, O2, O4 = np.eye(2), np.zeros((2, 2)), np.zeros((4, 4))
        B = np.diag(np.broadcast_to(np.asarray(process, float), 4))
        D = np.diag(np.broadcast_to(np.asarray(measurement, float), 4))
        return cls(A=np.block([[I2, T * I2], [O2, I2]]), E=np.block([[O2, dt * I2], [O2, O2]]),
                   B1=np.hstack([B, O4]), D1=np.hstack([O4, D]), C=np.eye(4), L=np.eye(4))

    @property
    def weight(self) -> float:
        """The largest noise weight (of B and D)."""
        return float(max(np.abs(self.B1).max(), np.abs(self.D1).max()))

    def scaled(self, s: float) -> ErrorSystem:
        """The same system with the noise weights B1, D1 divided by *s*."""
        return ErrorSystem(self.A, self.E, self.B1 / s, self.D1 / s, self.C, self.L)


def lmi(es: ErrorSystem, P, Q, g) -> list[list]:
    """The block rows of (2.15) for P, Q, g = gamma^2 (numpy arrays or cvxpy expressions):
    ``np.block`` or ``cvxpy.bmat`` of them is the matrix that must be negative definite."""
    n, m, p = es.A.shape[0], es.B1.shape[1], es.L.shape[0]
    O = np.zeros
    PAt = P @ es.A - Q @ es.C      # P A~
    PBt = P @ es.B1 - Q @ es.D1    # P B~
    PE = P @ es.E
    return [
        [-P, O((n, m)), PAt.T, PAt.T, es.L.T, PE.T],
        [O((m, n)), -g * np.eye(m), PBt.T, O((m, n)), O((m, p)), O((m, n))],
        [PAt, PBt, -P, O((n, n)), O((n, p)), O((n, n))],
        [PAt, O((n, m)), O((n, n)), -P, O((n, p)), O((n, n))],
        [es.L, O((p, m)), O((p, n)), O((p, n)), -np.eye(p), O((p, n))],
        [PE, O((n, m)), O((n, n)), O((n, n)), O((n, p)), -P],
    ]


@dataclass(frozen=True)
class HinfGain:
    """The filter (2.9) Af, Bf, its gamma (2.12), the LMI's P and Q, the system, the solve's time."""
    Af: np.ndarray
    Bf: np.ndarray
    gamma: float
    P: np.ndarray
    Q: np.ndarray
    system: ErrorSystem
    seconds: float


def _problem(es: ErrorSystem, g: float | None, eps: float):
    """cvxpy, P, Q, g (a variable when *g* is None) and the constraints: (2.15) <= -eps I
    (symmetrised: cvxpy's PSD constraint needs a symmetric expression; (2.15) is symmetric,
    its expression's rounding need not be) and P >= eps I."""
    cp = require("cvxpy", "lmi", WHO)
    require("clarabel", "lmi", WHO)
    n = es.A.shape[0]
    P = cp.Variable((n, n), symmetric=True)
    Q = cp.Variable((n, n))
    g = cp.Variable() if g is None else g
    M = cp.bmat(lmi(es, P, Q, g))
    k = M.shape[0]
    return cp, P, Q, g, [(M + M.T) / 2 << -eps * np.eye(k), P >> eps * np.eye(n)]


def solve_gain(T: float, dt: float, process, measurement, eps: float = EPS) -> HinfGain:
    """Minimise gamma^2 subject to (2.15) (2.22, 2.23); Bf = P^-1 Q, Af = A - Bf C (2.24, 2.25)."""
    es = ErrorSystem.build(T, dt, process, measurement)
    s = es.weight
    start = time.perf_counter()
    cp, P, Q, g, constraints = _problem(es.scaled(s), None, eps)
    problem = cp.Problem(cp.Minimize(g), constraints)
    problem.solve(solver=cp.CLARABEL)
    seconds = time.perf_counter() - start
    if problem.status != cp.OPTIMAL:
        raise HinfError(f"the H-infinity LMI (004 eq. 2.15) has no solution: Clarabel says "
                        f"{problem.status} (T={T}, dt={dt})")
    Bf = np.linalg.solve(P.value, Q.value)
    return HinfGain(Af=es.A - Bf @ es.C, Bf=Bf, gamma=s * float(np.sqrt(g.value)), P=P.value,
                    Q=Q.value, system=es, seconds=seconds)


def feasible(es: ErrorSystem, gamma: float, eps: float = EPS) -> bool:
    """Whether (2.15) with P >= eps I has a solution at this *gamma* (gamma^2 fixed)."""
    s = es.weight
    cp, _, _, _, constraints = _problem(es.scaled(s), (gamma / s) ** 2, eps)
    problem = cp.Problem(cp.Minimize(0), constraints)
    problem.solve(solver=cp.CLARABEL)
    return problem.status == cp.OPTIMAL


class HinfFilter:
    """The estimator (2.9): X^_{k+1} = Af X^_k + Bf Y_k, Z^ = L X^ (L = I: every state).

    Y_k is the INS - WSN difference of cycle k (2.5); the state after :meth:`step` is the
    estimate of the relative errors at the next cycle (2.9 is a one-step predictor)."""

    def __init__(self, gain: HinfGain):
        self.gain = gain
        self.x = np.zeros(gain.Af.shape[0])

    def step(self, Y) -> np.ndarray:
        self.x = self.gain.Af @ self.x + self.gain.Bf @ np.asarray(Y, float)
        return self.x

    def reset(self) -> None:
        """Back to X^ = 0 (2.8 starts from X_0 = 0)."""
        self.x = np.zeros_like(self.x)
