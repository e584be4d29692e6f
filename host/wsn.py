"""WSN positioning: anchor geometry, TOA and TDOA position fixes, TDMA cycles.

Ranges come from the four-timestamp exchange (000 eq. 6, ``protocols.nanoloc.distance``).
The tag moves on a level floor at a known height, so each 3-D range constrains the 2-D
position p = (x, y) (000 eqs. 10-11 with the height term)::

    r_i = sqrt(|p - a_i|^2 + dz_i^2),      dz_i = tag_height - z_i

TOA fix
    Closed-form start: linear least squares after differencing the squared ranges against
    their mean (every range enters alike, so no single reference range biases the start)::

        -2 (a_i - mean a)^T p = (r_i^2 - k_i) - mean(r^2 - k),   k_i = |a_i|^2 + dz_i^2

    then Gauss-Newton on r_i with Jacobian rows u_i^T = (p - a_i)^T / r_i. Covariance
    sigma^2 (J^T J)^-1, the CRLB at the solution (its trace root is sigma * HDOP).

TDOA fix (000 eqs. 12-13, reference anchor 1)
    d_i = r_i - r_ref for i != ref, noise R = sigma^2 (I + 1 1^T) because every difference
    shares the reference range's noise. Closed-form start by spherical intersection (SX):
    the differenced equations ``2 (a_i - a_ref)^T p = k_i - k_ref - d_i^2 - 2 d_i r_ref`` are
    solved for p = u + w r_ref in least squares, and r_ref from the quadratic
    ``r_ref^2 = |u + w r_ref - a_ref|^2 + dz_ref^2``. (Chan-Ho's method needs more anchors:
    with four anchors in a rectangle its first stage is singular on the symmetry axes.)
    Then Gauss-Newton weighted by R^-1, Jacobian rows (u_i - u_ref)^T. The quadratic's two
    roots are mirror positions; with three anchors both fit exactly, so a misfit difference
    below MIRROR_CHI2 does not choose: the plausible region does, then the previous fix
    (``near``), else there is no fix (docs/filters.md, "Mirror positions").

Outliers and plausibility
    The weighted residual sum of squares is chi-square with (equations - 2) degrees of
    freedom. When it exceeds the gate, each leave-one-out subset is solved and the best
    passing one is kept, but only if the subset keeps two degrees of freedom (TOA: five
    anchors, TDOA: six): with one left, a wrong subset's mirror solution can fit its ranges
    exactly (seen on the office layout), so four anchors give no fix instead. A fix outside
    the anchors' bounding box grown by ``margin_m`` is refused as well (TDOA's hyperbolae
    have far branches near the lines through two anchors).

TDMA cycle
    The anchors range the tag in turn (one exchange per anchor per 0.1 s cycle; in a field,
    the 13 to 21 anchors in range per 1 s cycle). A fix treats the ranges of one cycle as
    simultaneous, at the mean time of its exchanges: the tag moves at most v * cycle/2
    (2.5 cm at 0.5 m/s) in the meantime. (The EKF/UKF do not need this: they apply each
    range at its own time.) A cycle closes when every anchor has reported, on a repeat, or
    on an exchange more than ``cycle_s`` after its first: in a field only the last two can
    happen, so ``cycle_s`` must be shorter than the cycle by more than its start's jitter.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import combinations

import numpy as np

from .filters.linalg import solve
from .measurements import Fix

_ONES2 = np.ones(2)
_I2 = np.eye(2)
MIN_RANGES = 3  # TOA: 3 ranges for 2 unknowns; TDOA: 3 ranges give 2 differences
GN_ITERATIONS = 20
GN_TOLERANCE_M = 1e-6  # last step; Gauss-Newton converges quadratically from there
# still stepping this far after GN_ITERATIONS: hopping about a singular minimum (TDOA ranges no
# position fits), where the last iterate depends on the last bit of every product: no fix.
# (Slow, linear convergence, large residuals against raised anchors, is down to ~1e-5 m by then.)
GN_SETTLED_M = 1e-3
# SX roots whose weighted misfits (chi-square, in sigma units) differ by less than this fit the
# ranges alike (likelihoods within e^0.5): the ranges cannot choose, the geometry must (Solver)
MIRROR_CHI2 = 1.0


class AnchorLayout:
    """The surveyed anchors and the tag height: the geometry of every range.

    ``ids`` are sorted; solver and measurement functions take row indices (``index``).
    """

    def __init__(self, anchors: Mapping[int, Sequence[float]], tag_height: float = 0.0):
        if len(anchors) < 3:
            raise ValueError(f"need at least 3 anchors for a 2-D fix, got {len(anchors)}")
        items = sorted((int(i), tuple(p)) for i, p in anchors.items())
        self.ids = tuple(i for i, _ in items)
        xyz = np.array([[*p[:2], p[2] if len(p) > 2 else 0.0] for _, p in items], dtype=float)
        self.xy = xyz[:, :2].copy()
        self.z = xyz[:, 2].copy()
        self.tag_height = float(tag_height)
        self.dz = self.tag_height - self.z
        self._dz2 = self.dz**2
        self._row = {a: k for k, a in enumerate(self.ids)}
        # |r_a - r_b| <= the 3-D distance of anchors a and b, checked every cycle: computed when
        # a pair is first asked (a field of 1400 anchors has 2 M pairs, a cycle asks 20)
        self._baselines: dict[tuple[int, int], float] = {}

    def index(self, anchors: Sequence[int]) -> np.ndarray:
        return np.array([self._row[a] for a in anchors], dtype=np.intp)

    def __contains__(self, anchor: int) -> bool:
        return anchor in self._row

    def _offsets(self, p: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """p - a_i (horizontal) and the 3-D ranges (take, not fancy indexing: faster)."""
        d = p - self.xy.take(idx, 0)
        return d, np.sqrt((d * d).dot(_ONES2) + self._dz2.take(idx))

    def ranges(self, p: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """3-D ranges from tag positions ``p`` (..., m, 2) or (..., 1, 2) to anchors ``idx``."""
        return self._offsets(p, idx)[1]

    def geometry(self, p: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ranges (m,) from a position (2,) (or one per anchor, (m, 2)) and d r / d p (m, 2);
        stacked, (..., m) and (..., m, 2) from positions (..., m, 2) (host.batch.model).
        At an anchor of the tag's height (r = 0, the apex of the range's cone, where it has
        no gradient) d r / d p is its subgradient 0: that range says nothing of the
        direction there, where 0/0 made a filter's state NaN (a track linearised at a start
        put on an anchor, as outage-bridging's is)."""
        d, r = self._offsets(p, idx)
        if r.all():
            return r, d / r[..., None]
        return r, np.divide(d, r[..., None], out=np.zeros_like(d), where=r[..., None] > 0)

    def baseline(self, a: int, b: int) -> float:
        """3-D distance between anchors a and b (ids): the bound on |r_a - r_b|."""
        d = self._baselines.get((a, b))
        if d is None:
            i, j = self._row[a], self._row[b]
            d = self._baselines[a, b] = float(np.hypot(np.linalg.norm(self.xy[i] - self.xy[j]),
                                                       self.z[i] - self.z[j]))
        return d

    def hdop(self, p: np.ndarray, idx: np.ndarray | None = None) -> float:
        """sqrt(tr((G^T G)^-1)), G rows = u_i^T: RMSE >= sigma * HDOP (TOA CRLB)."""
        idx = np.arange(len(self.ids)) if idx is None else idx
        _, g = self.geometry(np.asarray(p, float), idx)
        return float(np.sqrt(np.trace(np.linalg.inv(g.T @ g))))


@lru_cache(maxsize=64)
def tdoa_covariance(sigma: float, m: int) -> np.ndarray:
    """R = sigma^2 (I + 1 1^T) of the m range differences to one reference range.
    Cached, so read-only."""
    R = sigma**2 * (np.eye(m) + np.ones((m, m)))
    R.flags.writeable = False
    return R


@lru_cache(maxsize=64)
def tdoa_whitening(sigma: float, m: int) -> np.ndarray:
    """W^1/2 with W^1/2^T W^1/2 = R^-1 (Cholesky factor of R^-1): whitened, the weighted
    least squares of the m differences is an ordinary one. Cached, so read-only."""
    w = np.linalg.cholesky(np.linalg.inv(tdoa_covariance(sigma, m))).T
    w.flags.writeable = False
    return w


@lru_cache(maxsize=64)
def chi2_gate(dof: int, probability: float) -> float:
    """Squared-Mahalanobis threshold passing *probability* of consistent innovations."""
    from scipy.stats import chi2  # here: scipy.stats costs every navtwin command ~0.7 s to import

    return float(chi2.ppf(probability, dof))


def toa_linear(layout: AnchorLayout, idx: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Closed-form TOA position: squared ranges differenced against their mean."""
    a = layout.xy[idx]
    k = np.einsum("ij,ij->i", a, a) + layout.dz[idx] ** 2
    rhs = r**2 - k
    A = -2.0 * (a - a.mean(axis=0))
    return np.linalg.lstsq(A, rhs - rhs.mean(), rcond=None)[0]


@lru_cache(maxsize=64)
def _sx_geometry(layout: AnchorLayout, rows: tuple[int, ...], ref: int) -> tuple[np.ndarray, np.ndarray]:
    """pinv(G), G = 2 (a_i - a_ref), and k_i - k_ref of the SX equations: the survey's alone,
    so computed once per anchor set (a fixed layout has a handful)."""
    idx = np.array(rows, dtype=np.intp)
    a_ref = layout.xy[ref]
    a = layout.xy[idx]
    k = np.einsum("ij,ij->i", a, a) + layout.dz[idx] ** 2
    k_ref = a_ref @ a_ref + layout.dz[ref] ** 2
    return np.linalg.pinv(2.0 * (a - a_ref)), k - k_ref


def tdoa_closed_form(layout: AnchorLayout, idx: np.ndarray, d: np.ndarray, ref: int,
                     weight_sqrt: np.ndarray) -> list[np.ndarray]:
    """Spherical-intersection (SX) TDOA positions; ``d`` = r_i - r_ref for rows idx != ref,
    ``weight_sqrt`` their whitening. The quadratic's root that fits the differences best; both
    (in root order, not misfit order) when their weighted misfits differ by less than
    ``MIRROR_CHI2``: mirror solutions the ranges cannot tell apart, for the caller to resolve."""
    a_ref = layout.xy[ref]
    pinv, dk = _sx_geometry(layout, tuple(idx.tolist()), int(ref))
    u = pinv.dot(dk - d**2)
    w = pinv.dot(-2.0 * d)
    e = u - a_ref
    qa, qb, qc = w.dot(w) - 1.0, 2.0 * w.dot(e), e.dot(e) + layout.dz[ref] ** 2
    if abs(qa) < 1e-12:
        roots = np.array([-qc / qb]) if qb else np.array([0.0])
    else:
        disc = qb * qb - 4.0 * qa * qc
        # No real root: the noise pushed the quadratic past tangency; take its vertex.
        roots = (np.array([-qb / (2 * qa)]) if disc < 0
                 else (-qb + np.array([1.0, -1.0]) * np.sqrt(disc)) / (2 * qa))
    roots = roots[roots >= 0.0] if np.any(roots >= 0.0) else np.array([0.0])
    candidates = [u + w * r0 for r0 in roots]
    if len(candidates) == 1:
        return candidates

    def misfit(p):
        e = layout.ranges(p[None], idx) - layout.ranges(p[None], np.array([ref])) - d
        e = weight_sqrt.dot(e)
        return e.dot(e)

    chi2 = [misfit(p) for p in candidates]
    if abs(chi2[0] - chi2[1]) < MIRROR_CHI2:
        return candidates
    return [candidates[int(chi2[1] < chi2[0])]]


def _gauss_newton(residual_jacobian, p0: np.ndarray, weight_sqrt: np.ndarray):
    """Minimise |W^1/2 e(p)|^2; returns p, (J^T W J)^-1 and the weighted RSS."""
    p = np.asarray(p0, float).copy()
    for _ in range(GN_ITERATIONS):
        e, J = residual_jacobian(p)
        ew, Jw = weight_sqrt.dot(e), weight_sqrt.dot(J)
        step = solve(Jw.T.dot(Jw), -Jw.T.dot(ew))  # LAPACK: ill-conditioned in a corridor
        p += step
        if not (math.isfinite(p[0]) and math.isfinite(p[1])):
            raise np.linalg.LinAlgError("Gauss-Newton diverged")
        if step.dot(step) < GN_TOLERANCE_M**2:
            break
    else:
        if step.dot(step) > GN_SETTLED_M**2:
            raise np.linalg.LinAlgError("Gauss-Newton did not converge")
    e, J = residual_jacobian(p)
    ew, Jw = weight_sqrt.dot(e), weight_sqrt.dot(J)
    return p, solve(Jw.T.dot(Jw), _I2), float(ew.dot(ew))


def toa_fix(layout: AnchorLayout, idx: np.ndarray, r: np.ndarray, sigma: float):
    """Gauss-Newton TOA fix from the closed-form start: (p, cov, chi2)."""
    def rj(p):
        rho, J = layout.geometry(p, idx)
        return rho - r, J

    return _gauss_newton(rj, toa_linear(layout, idx, r), np.eye(len(idx)) / sigma)


def tdoa_fix(layout: AnchorLayout, idx: np.ndarray, r: np.ndarray, sigma: float, ref_row: int,
             resolve):
    """Gauss-Newton TDOA fix (differences to row ``ref_row`` of idx): (p, cov, chi2).
    ``resolve`` picks the start from mirror SX positions that fit alike."""
    others = np.array([k for k in range(len(idx)) if k != ref_row], dtype=np.intp)
    ref = idx[ref_row]
    d = r[others] - r[ref_row]
    w_sqrt = tdoa_whitening(sigma, len(others))

    def rj(p):
        rho, J = layout.geometry(p, idx)
        return (rho.take(others) - rho[ref_row]) - d, J.take(others, 0) - J[ref_row]

    starts = tdoa_closed_form(layout, idx[others], d, ref, w_sqrt)
    return _gauss_newton(rj, starts[0] if len(starts) == 1 else resolve(starts), w_sqrt)


@dataclass(slots=True)
class Solver:
    """Position fixes from the ranges of one cycle, TOA or TDOA, with outlier gating."""

    layout: AnchorLayout
    sigma: float
    method: str = "toa"  # "toa" | "tdoa"
    reference: int = 1  # TDOA reference anchor; the lowest present id stands in if it is missing
    gate_probability: float = 0.9999
    margin_m: float | None = 2.0  # plausible region: anchors' bounding box grown by this

    _box: tuple[float, float, float, float] | None = field(init=False, default=None, repr=False)

    def __post_init__(self):
        if self.method not in ("toa", "tdoa"):
            raise ValueError(f"WSN method {self.method!r}: use 'toa' or 'tdoa'")
        if self.margin_m is not None:
            (x0, y0), (x1, y1) = self.layout.xy.min(axis=0), self.layout.xy.max(axis=0)
            m = self.margin_m
            self._box = (x0 - m, y0 - m, x1 + m, y1 + m)

    def _inside(self, p: np.ndarray) -> bool:
        if self._box is None:
            return True
        x0, y0, x1, y1 = self._box
        return bool(x0 <= p[0] <= x1 and y0 <= p[1] <= y1)

    def inside(self, p: np.ndarray) -> np.ndarray:
        """Whether each position of p (n, 2) is in the plausible region (host.batch.wsn; one
        position: ``_inside``, plain floats being faster there)."""
        if self._box is None:
            return np.ones(len(p), bool)
        x0, y0, x1, y1 = self._box
        return (x0 <= p[:, 0]) & (p[:, 0] <= x1) & (y0 <= p[:, 1]) & (p[:, 1] <= y1)

    def _dof(self, m: int) -> int:
        return m - 2 if self.method == "toa" else m - 3

    def _solve(self, anchors: tuple[int, ...], r: np.ndarray, near: np.ndarray | None):
        idx = self.layout.index(anchors)
        if self.method == "toa":
            return toa_fix(self.layout, idx, r, self.sigma)
        ref_row = anchors.index(self.reference) if self.reference in anchors else 0
        return tdoa_fix(self.layout, idx, r, self.sigma, ref_row,
                        lambda candidates: self._resolve(candidates, near))

    def _resolve(self, candidates: list[np.ndarray], near: np.ndarray | None) -> np.ndarray:
        """Of mirror positions that fit the ranges alike: the one in the plausible region,
        else the one nearer ``near``; with neither to tell them apart, no fix."""
        inside = [p for p in candidates if self._inside(p)]
        if len(inside) < 2:
            return (inside or candidates)[0]  # none inside: refused as "outside" anyway
        if near is None:
            raise np.linalg.LinAlgError("mirror positions fit alike")  # "geometry"
        return min(inside, key=lambda p: float(np.hypot(*(p - near))))

    def _passes(self, m: int, rss: float) -> bool:
        dof = self._dof(m)
        return dof < 1 or rss <= chi2_gate(dof, self.gate_probability)

    def fix(self, t: float, anchors: Sequence[int], ranges: Sequence[float],
            near: Sequence[float] | None = None) -> Fix | str:
        """A :class:`Fix`, or why there is none: ``"too_few"`` ranges, ``"geometry"``
        (singular, diverging or not settling, e.g. collinear anchors or ranges no position
        fits, or TDOA mirror positions that fit alike, both plausible and no ``near``),
        ``"outside"`` the plausible region, ``"residual"`` (inconsistent ranges and no
        consistent subset). ``near``: where the tag was lately (the previous fix), to choose
        between mirror positions."""
        order = sorted(range(len(anchors)), key=anchors.__getitem__)  # stable
        anchors = tuple(int(anchors[k]) for k in order)
        r = np.array([float(ranges[k]) for k in order])
        near = None if near is None else np.asarray(near, float)
        m = len(anchors)
        if m < MIN_RANGES:
            return "too_few"
        result = self._checked(t, anchors, r, near)
        if not isinstance(result, Fix) or self._passes(m, result.chi2):
            return result
        if self._dof(m - 1) < 2:
            return "residual"
        best = None
        for keep in combinations(range(m), m - 1):
            sub = self._checked(t, tuple(anchors[k] for k in keep), r[list(keep)], near)
            if isinstance(sub, Fix) and self._passes(m - 1, sub.chi2) and (best is None or sub.chi2 < best.chi2):
                best = sub
        if best is None:
            return "residual"
        return Fix(t, best.p, best.cov, best.anchors, best.chi2, tuple(a for a in anchors if a not in best.anchors))

    def _checked(self, t: float, anchors: tuple[int, ...], r: np.ndarray,
                 near: np.ndarray | None) -> Fix | str:
        try:
            p, cov, rss = self._solve(anchors, r, near)
        except np.linalg.LinAlgError:
            return "geometry"
        return Fix(t, p, cov, anchors, rss) if self._inside(p) else "outside"


@dataclass(slots=True)
class Cycle:
    """The exchanges of one TDMA cycle: every report, and the usable distances."""

    times: list[float] = field(default_factory=list)
    anchors: list[int] = field(default_factory=list)
    valid_anchors: list[int] = field(default_factory=list)
    valid_times: list[float] = field(default_factory=list)
    distances: list[float] = field(default_factory=list)

    @property
    def t(self) -> float:
        """Time of the fix: the mean time of the usable exchanges."""
        return sum(self.valid_times) / len(self.valid_times) if self.valid_times else self.times[-1]


class CycleGrouper:
    """Groups exchange reports into TDMA cycles.

    A cycle closes when every anchor has reported (complete or not), when an anchor reports
    a second time, or when an exchange comes more than ``window_s`` after the cycle's first.
    """

    def __init__(self, n_anchors: int, window_s: float = 0.1):
        self.n_anchors = n_anchors
        self.window_s = window_s
        self._open: Cycle | None = None

    def add(self, t: float, anchor: int, distance: float | None) -> list[Cycle]:
        closed = []
        c = self._open
        if c is not None and (anchor in c.anchors or t - c.times[0] > self.window_s):
            closed.append(c)
            c = None
        if c is None:
            c = self._open = Cycle()
        c.times.append(t)
        c.anchors.append(anchor)
        if distance is not None:
            c.valid_anchors.append(anchor)
            c.valid_times.append(t)
            c.distances.append(distance)
        if len(c.anchors) >= self.n_anchors:
            closed.append(c)
            self._open = None
        return closed
