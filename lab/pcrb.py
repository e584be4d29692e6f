"""A posterior Cramer-Rao bound for the fusion tracks' position, along the true path.

Which bound, exactly. The PCRB of Tichavsky, Muravchik and Nehorai (1998) for the model the
fusion tracks assume (host.filters.model): the constant-acceleration state
x = [x, y, vx, vy, ax, ay] with the host config's white-jerk ``jerk_psd`` (F(dt), Q(dt)
exact), the prior N(start, P0) of the host config's ``p0_sigma`` at scenario time 0, and as
the only measurements the emulator's ranges: one per anchor per TDMA cycle at its slot's
time (the scenario's ``[ranging]`` ``start_ms``, ``cycle_ms``, ``slot_ms``, ``slot_order``),
3-D distance from the anchor's antenna to the tag's, noise sigma(d) = sigma0_m +
sigma_per_m d (docs/emulator-models.md; no range bias, no NLOS, no timeout). The
information matrix follows

    J_{k+1} = D22 - D21 (J_k + D11)^-1 D12,
    D11 = F^T Q^-1 F,  D12 = D21^T = -F^T Q^-1,  D22 = Q^-1 + H_{k+1}^T R_{k+1}^-1 H_{k+1},

with H the ranges' Jacobian at the TRUE position of the exchange (the truth, not an
expectation over trajectories: the bound is conditional on the path driven). With a linear
measurement this is the Kalman filter's information recursion, so the bound is the
covariance of the best filter of that model. It is a bound on an estimator that uses the
ranges alone: the tracks also take the SINS accelerations and the at-rest updates of the
alignment, which this bound does not credit, and the emulated vehicle does not move as the
white-jerk model says; a track below the curve is therefore possible and not an error.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from navtwin.emulator.scenario import Scenario
from navtwin.host.filters.model import DIM_X, ConstantAcceleration


def information(model: ConstantAcceleration, J0: np.ndarray,
                steps: Iterable[tuple[float, np.ndarray, np.ndarray]]) -> list[np.ndarray]:
    """The information matrices J_1, J_2, ... after each ``(dt, H, R)`` step (a predict by dt,
    then the measurement z = H x + v, v ~ N(0, R); dt = 0 adds a measurement at the same
    time), from J_0 at time 0."""
    out, J = [], np.asarray(J0, float)
    for dt, H, R in steps:
        if dt == 0:  # another measurement at the same time: Q = 0, its information adds
            J = J + H.T @ np.linalg.solve(R, H)
            out.append(J)
            continue
        # Tichavsky's D22 - D21 (J + D11)^-1 D12 is, by the matrix inversion lemma (F is
        # invertible), (F J^-1 F^T + Q)^-1 + H^T R^-1 H: the same recursion without Q^-1,
        # whose condition number grows as dt^-4 (tests/lab/test_pcrb.py computes both)
        P = model.propagate(np.zeros(DIM_X), np.linalg.inv(J), dt)[1]
        J = np.linalg.inv(P) + H.T @ np.linalg.solve(R, H)
        J = (J + J.T) / 2  # symmetric to the rounding
        out.append(J)
    return out


def exchanges(sc: Scenario, duration_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Scenario time (s) and anchor index (in ``sc.all_anchors``) of every scheduled exchange
    before *duration_s*, in time order."""
    r = sc.ranging
    index = {a.id: i for i, a in enumerate(sc.all_anchors)}
    slots = [(s * r.slot_ms, index[a]) for s, a in enumerate(sc.slot_order)]
    cycles = np.arange(0.0, duration_s * 1e3, r.cycle_ms)
    t = np.array([(r.start_ms + c + off) / 1e3 for c in cycles for off, _ in slots])
    anchor = np.array([i for _ in cycles for _, i in slots], dtype=np.intp)
    keep = t < duration_s
    return t[keep], anchor[keep]


def position_bound(sc: Scenario, truth: dict, jerk_psd: float, p0_sigma) -> dict[str, np.ndarray]:
    """``t`` (s, one per exchange) and ``rms``: sqrt(trace) of the bound's position block (m),
    the least RMS horizontal error the module docstring's estimator can have at t."""
    t, which = exchanges(sc, float(truth["t"][-1]))
    anchors = np.array([sc.anchor_position(a) for a in sc.all_anchors])[which]
    tag = np.column_stack((np.interp(t, truth["t"], truth["x"]), np.interp(t, truth["t"], truth["y"]),
                           np.full(len(t), sc.tag.z)))
    diff = tag - anchors
    d = np.linalg.norm(diff, axis=1)
    H = np.zeros((len(t), 1, DIM_X))
    H[:, 0, :2] = diff[:, :2] / d[:, None]  # d r / d (x, y) at the true position
    R = ((sc.ranging.sigma0_m + sc.ranging.sigma_per_m * d) ** 2)[:, None, None]
    sp, sv, sa = p0_sigma
    J0 = np.diag(1 / np.array([sp, sp, sv, sv, sa, sa]) ** 2)
    dts = np.diff(t, prepend=0.0)
    J = information(ConstantAcceleration(jerk_psd), J0, zip(dts, H, R))
    rms = np.array([np.sqrt(np.trace(np.linalg.inv(j)[:2, :2])) for j in J])
    return {"t": t, "rms": rms}
