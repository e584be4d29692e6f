"""A posterior Cramer-Rao bound for the fusion tracks' position, along the true path.

Which bound, exactly. The PCRB of Tichavsky, Muravchik and Nehorai (1998) for the model the
fusion tracks assume (host.filters.model): the constant-acceleration state
x = [x, y, vx, vy, ax, ay] with the host config's white-jerk ``jerk_psd`` (F(dt), Q(dt)
exact), the prior N(start, P0) of the host config's ``p0_sigma`` at scenario time 0, and as
the only measurements the emulator's ranges: one per exchange of its TDMA schedule, at its
time (emulator.tdma: with ``slots`` one per anchor per cycle, ``in-range`` the anchors near
the tag at each cycle start),
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
from navtwin.emulator.world import World
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
    before *duration_s*, in time order: the emulator's own TDMA schedule (emulator.tdma; the
    in-range one picks its anchors by the tag's true position, and any cycle jitter is the
    scenario seed's), less the exchanges beyond the radio range, which give no report; of vehicle
1's tag, with several on one network."""
    net = World(sc).nanoloc  # vehicle 1's: of a network several tags share, its cycles
    idx, k, t0, _ = net.schedule.block(0, round(duration_s * 1e9))
    order = np.argsort(t0, kind="stable")
    order = order[k[order] % len(net.tags) == 0]
    idx, k, t0 = idx[order], k[order], t0[order]
    if sc.ranging.radio_range_m is not None:
        far = np.linalg.norm(net.tag_position(k, t0) - net.positions[idx], axis=1)
        keep = far <= sc.ranging.radio_range_m
        idx, t0 = idx[keep], t0[keep]
    index = {a.id: i for i, a in enumerate(sc.all_anchors)}
    return t0 / 1e9, np.array([index[a] for a in net.ids[idx].tolist()], dtype=np.intp)


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
    # d r / d (x, y) at the true position; none with the tag at the antenna (a grid node under
    # outage-bridging's start): there the range says nothing of the direction
    H[:, 0, :2] = np.divide(diff[:, :2], d[:, None], out=np.zeros((len(t), 2)), where=d[:, None] > 0)
    R = ((sc.ranging.sigma0_m + sc.ranging.sigma_per_m * d) ** 2)[:, None, None]
    sp, sv, sa = p0_sigma
    J0 = np.diag(1 / np.array([sp, sp, sv, sv, sa, sa]) ** 2)
    dts = np.diff(t, prepend=0.0)
    J = information(ConstantAcceleration(jerk_psd), J0, zip(dts, H, R))
    rms = np.array([np.sqrt(np.trace(np.linalg.inv(j)[:2, :2])) for j in J])
    return {"t": t, "rms": rms}
