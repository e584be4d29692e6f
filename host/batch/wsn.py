"""WSN fixes of many seeds' TDMA cycles at once (host.wsn.Solver, TDOA, batched).

The common path of :meth:`host.wsn.Solver.fix` with ``method = "tdoa"``, for the cycles of
one anchor set stacked: the spherical-intersection start (000 eqs. 12-13's closed form, its
root that fits best), Gauss-Newton from there, the CRLB covariance, the plausible region and
the chi-square test of the residual. Each step is the per-cycle one on stacked operands
(stacked ``np.matmul`` for the products, LAPACK's gesv for the 2x2 solves:
host.batch.linalg.solve_each), so a
fix equals Solver.fix's. A cycle off that path (mirror positions that fit alike, a
degenerate quadratic, a Gauss-Newton that diverges or does not settle, a residual that fails
the test and needs the outlier search) is solved by Solver.fix itself: the fixes are the
solver's in every case, the batch only makes the usual ones cheaper. TOA fixes (004's
``wsn_method = "toa"``) go to Solver.fix one by one. :func:`solved` takes the cycles as
arrays (host.batch.ranging's), :func:`fixes` as Solver.fix's arguments.
"""
from __future__ import annotations

import numpy as np

from navtwin.host.measurements import Fix
from navtwin.host.wsn import (GN_ITERATIONS, GN_SETTLED_M, GN_TOLERANCE_M, MIN_RANGES, MIRROR_CHI2,
                              Solver, _sx_geometry, chi2_gate, tdoa_whitening)

from .linalg import T, dot, mv, solve_each

_ONES2 = np.ones(2)
_I2 = np.eye(2)


def fixes(solver: Solver, cycles: list) -> list:
    """Solver.fix of each ``(t, anchors, ranges, near)`` in *cycles*: a Fix or the reason
    there is none, in order."""
    layout = solver.layout
    w = max((len(c[1]) for c in cycles), default=0)
    rows, r = np.zeros((len(cycles), w), np.intp), np.zeros((len(cycles), w))
    count = np.array([len(c[1]) for c in cycles], np.intp)
    near = np.full((len(cycles), 2), np.nan)
    for k, (_, anchors, ranges, p) in enumerate(cycles):
        rows[k, :count[k]], r[k, :count[k]] = layout.index(anchors), ranges
        if p is not None:
            near[k] = p
    t = np.array([c[0] for c in cycles], float)
    p, cov, rss, answers = solved(solver, t, rows, r, count, near)
    return [answers[k] if k in answers else
            Fix(cycles[k][0], p[k].copy(), cov[k].copy(),
                tuple(sorted(int(a) for a in cycles[k][1])), float(rss[k]))
            for k in range(len(cycles))]


def solved(solver: Solver, t: np.ndarray, rows: np.ndarray, ranges: np.ndarray, count: np.ndarray,
           near: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Solver.fix of k cycles given as arrays: cycle j's anchors are the layout rows
    ``rows[j, :count[j]]`` (any order, no repeat), its ranges ``ranges[j, :count[j]]``, its
    time t[j], the previous fix ``near[j]`` (NaN: none). Returns p (k, 2), cov (k, 2, 2)
    and the weighted RSS (k,) of the cycles that took the common path, and Solver.fix's
    answer (a Fix or the reason there is none) for each other cycle j, as ``{j: answer}``."""
    k = len(t)
    p, cov, rss = np.zeros((k, 2)), np.zeros((k, 2, 2)), np.zeros(k)
    answers: dict = {}
    common = count >= MIN_RANGES if solver.method == "tdoa" else np.zeros(k, bool)
    if common.any():  # grouped by anchor set: the anchors sorted, as Solver.fix sorts them
        j = np.flatnonzero(common)
        n_anchors = len(solver.layout.ids)
        padded = np.where(np.arange(rows.shape[1]) < count[j, None], rows[j], n_anchors)
        order = np.argsort(padded, 1, kind="stable")
        sets, group = np.unique(np.take_along_axis(padded, order, 1), axis=0, return_inverse=True)
        group = group.ravel()
        for g, s in enumerate(sets):
            m = int((s < n_anchors).sum())
            members = j[group == g]
            r = np.take_along_axis(ranges[members], order[group == g, :m], 1)
            anchors = tuple(solver.layout.ids[a] for a in s[:m].tolist())
            ok, p[members], cov[members], rss[members] = _tdoa(solver, anchors, r)
            common[members[~ok]] = False
    ids = np.asarray(solver.layout.ids)
    for j in np.flatnonzero(~common).tolist():
        m = count[j]
        answers[j] = solver.fix(float(t[j]), tuple(ids[rows[j, :m]].tolist()), ranges[j, :m].tolist(),
                                None if np.isnan(near[j, 0]) else near[j])
    return p, cov, rss, answers


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
        step[going], singular = solve_each(np.matmul(T(Jw), Jw), -mv(T(Jw), ew))
        ok[going[singular]] = False
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
    cov[rows], singular = solve_each(A, np.broadcast_to(_I2, A.shape))
    ok[rows[singular]] = False
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
