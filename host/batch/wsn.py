"""WSN fixes of many seeds' TDMA cycles at once (host.wsn.Solver, TDOA, batched).

The common path of :meth:`host.wsn.Solver.fix` with ``method = "tdoa"``, for the cycles of
one anchor set stacked: the spherical-intersection start (000 eqs. 12-13's closed form, its
root that fits best), Gauss-Newton from there, the CRLB covariance, the plausible region and
the chi-square test of the residual. Each step is the per-cycle one on stacked operands
(stacked ``np.matmul`` for the products, LAPACK's gesv per cycle for the 2x2 solves), so a
fix equals Solver.fix's. A cycle off that path (mirror positions that fit alike, a
degenerate quadratic, a Gauss-Newton that diverges or does not settle, a residual that fails
the test and needs the outlier search) is solved by Solver.fix itself: the fixes are the
solver's in every case, the batch only makes the usual ones cheaper. TOA fixes (004's
``wsn_method = "toa"``) go to Solver.fix one by one.
"""
from __future__ import annotations

import numpy as np

from navtwin.host.filters.linalg import solve
from navtwin.host.measurements import Fix
from navtwin.host.wsn import (GN_ITERATIONS, GN_SETTLED_M, GN_TOLERANCE_M, MIN_RANGES, MIRROR_CHI2,
                              Solver, _sx_geometry, chi2_gate, tdoa_whitening)

from .linalg import T, dot, mv

_ONES2 = np.ones(2)
_I2 = np.eye(2)


def fixes(solver: Solver, cycles: list) -> list:
    """Solver.fix of each ``(t, anchors, ranges, near)`` in *cycles*: a Fix or the reason
    there is none, in order."""
    out: list = [None] * len(cycles)
    groups: dict[tuple[int, ...], list] = {}
    for k, (t, anchors, ranges, near) in enumerate(cycles):
        order = sorted(range(len(anchors)), key=anchors.__getitem__)
        key = tuple(int(anchors[j]) for j in order)
        if solver.method != "tdoa" or len(key) < MIN_RANGES:
            out[k] = solver.fix(t, anchors, ranges, near)
        else:
            groups.setdefault(key, []).append((k, [float(ranges[j]) for j in order]))
    for anchors, members in groups.items():
        ok, p, cov, rss = _tdoa(solver, anchors, np.array([r for _, r in members]))
        for j, (k, _) in enumerate(members):
            out[k] = Fix(cycles[k][0], p[j].copy(), cov[j].copy(), anchors, float(rss[j])) \
                if ok[j] else solver.fix(*cycles[k])
    return out


def _tdoa(solver: Solver, anchors: tuple[int, ...], r: np.ndarray):
    """The common path for the cycles of one anchor set (ranges *r* (n, m), sorted by
    anchor): which took it, and their p (n, 2), cov (n, 2, 2) and weighted RSS (n,)."""
    layout = solver.layout
    idx = layout.index(anchors)
    m, n = len(anchors), len(r)
    ref_row = anchors.index(solver.reference) if solver.reference in anchors else 0
    others = np.array([k for k in range(m) if k != ref_row], dtype=np.intp)
    ref = int(idx[ref_row])
    d = r[:, others] - r[:, ref_row:ref_row + 1]
    w_sqrt = tdoa_whitening(solver.sigma, len(others))
    ok = np.ones(n, bool)
    p = _start(layout, idx[others], d, ref, w_sqrt, ok)

    def rj(q, rows):
        """Solver's tdoa_fix residual and Jacobian at positions q of the cycles *rows*."""
        dd = q[:, None, :] - layout.xy[idx]
        rho = np.sqrt((dd * dd).dot(_ONES2) + (layout.dz ** 2)[idx])
        J = dd / rho[..., None]
        return ((rho[:, others] - rho[:, ref_row:ref_row + 1]) - d[rows],
                J[:, others] - J[:, ref_row:ref_row + 1])

    going = np.flatnonzero(ok)
    step = np.zeros((n, 2))
    for _ in range(GN_ITERATIONS):  # Solver's _gauss_newton, the cycles still stepping
        if not going.size:
            break
        e, J = rj(p[going], going)
        ew, Jw = mv(w_sqrt, e), np.matmul(w_sqrt, J)
        A, b = np.matmul(T(Jw), Jw), -mv(T(Jw), ew)
        for j, k in enumerate(going.tolist()):
            try:
                step[k] = solve(A[j], b[j])
            except np.linalg.LinAlgError:
                ok[k] = False
        p[going] += step[going]
        ok &= np.isfinite(p).all(1)
        going = going[ok[going] & (dot(step[going], step[going]) >= GN_TOLERANCE_M ** 2)]
    else:  # still stepping after every iteration: settled, or hopping about (the solver's)
        ok[going] &= dot(step[going], step[going]) <= GN_SETTLED_M ** 2
    rows = np.flatnonzero(ok)
    e, J = rj(p[rows], rows)
    ew, Jw = mv(w_sqrt, e), np.matmul(w_sqrt, J)
    A = np.matmul(T(Jw), Jw)
    cov = np.zeros((n, 2, 2))
    for j, k in enumerate(rows.tolist()):
        try:
            cov[k] = solve(A[j], _I2)
        except np.linalg.LinAlgError:
            ok[k] = False
    rss = np.zeros(n)
    rss[rows] = dot(ew, ew)
    ok &= solver.inside(p) & _passes(solver, m, rss)
    return ok, p, cov, rss


def _start(layout, idx, d, ref: int, w_sqrt, ok) -> np.ndarray:
    """host.wsn.tdoa_closed_form's single best root per cycle; a cycle whose roots fit alike
    (mirror positions, for the solver to resolve) or whose quadratic degenerates leaves *ok*."""
    a_ref = layout.xy[ref]
    pinv, dk = _sx_geometry(layout, tuple(idx.tolist()), ref)
    u = mv(pinv, dk - d ** 2)
    w = mv(pinv, -2.0 * d)
    e = u - a_ref
    qa, qb, qc = dot(w, w) - 1.0, 2.0 * dot(w, e), dot(e, e) + layout.dz[ref] ** 2
    ok &= np.abs(qa) >= 1e-12
    disc = qb * qb - 4.0 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.sqrt(disc)
        first, second = (-qb + s) / (2 * qa), (-qb - s) / (2 * qa)
        vertex = -qb / (2 * qa)
    # no real root: the vertex; else the roots not behind the reference, 0 if none is
    first = np.where(disc < 0, vertex, first)
    both = (disc >= 0) & (first >= 0.0) & (second >= 0.0)
    root = np.where(first >= 0.0, first, np.where((disc >= 0) & (second >= 0.0), second, 0.0))
    p = u + w * root[:, None]
    if both.any():  # two candidates: the one that fits best, unless they fit alike
        k = np.flatnonzero(both)
        other = u[k] + w[k] * second[k, None]
        chi = [_misfit(layout, idx, ref, d[k], w_sqrt, q) for q in (p[k], other)]
        ok[k] &= np.abs(chi[0] - chi[1]) >= MIRROR_CHI2
        take = chi[1] < chi[0]
        p[k[take]] = other[take]
    return p


def _misfit(layout, idx, ref, d, w_sqrt, q) -> np.ndarray:
    """tdoa_closed_form's weighted misfit of positions q (n, 2) to the differences d."""
    def ranges(rows):
        dd = q[:, None, :] - layout.xy[rows]
        return np.sqrt((dd * dd).dot(_ONES2) + (layout.dz ** 2)[rows])
    e = mv(w_sqrt, ranges(idx) - ranges(np.array([ref])) - d)
    return dot(e, e)


def _passes(solver: Solver, m: int, rss: np.ndarray) -> np.ndarray:
    dof = m - 3
    return np.ones(len(rss), bool) if dof < 1 else rss <= chi2_gate(dof, solver.gate_probability)
