"""003's centroid and weighted centroid of three range circles (003 section 2.2, eqs. 9-12;
docs/filters.md, "003's tracks").

Three anchors at centres c_1, c_2, c_3 (the nearest: the strongest RSSI) with horizontal
ranges r_1, r_2, r_3 give three points, one per pair of circles (:func:`vertex`):

* A of circles 1 and 2, B of 2 and 3, C of 3 and 1 (the paper's Figure 2);
* two intersections: the one closer to the third circle, i.e. with the smaller
  | |p - c_k| - r_k |; the paper's "which is outside the two circles" adds nothing that
  rule does not decide, so it is not applied (a tie, as in a symmetric layout: the first of
  the two, on the left of c_i -> c_j);
* one intersection (tangent circles): that point;
* none, the circles apart: the midpoint of the centres (the paper's rule);
* none, one circle inside the other: the paper's "no intersection" rule applies as
  written, the midpoint of the centres too (not a rule of ours: the paper does not tell
  the two cases apart).

The centroid (eqs. 9-10) is their mean; the weighted centroid (eqs. 11-12) weighs A, B, C
by 1/(r_1 + r_2), 1/(r_2 + r_3), 1/(r_3 + r_1): a point fixed by shorter ranges counts more.

Degenerate input never raises: :class:`Result` has ``p`` None and a ``reason``
(``range_invalid``: a range not finite or not positive; ``coincident_anchors``: two
centres one point, whose circles have no defined intersection or midpoint rule).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Result:
    """A fix ``p`` (2,) with the ``vertices`` A, B, C (3, 2) it came from, or ``p`` None and
    the ``reason``."""

    p: np.ndarray | None
    vertices: np.ndarray | None = None
    reason: str | None = None


#: The circle pairs of A, B, C and each pair's third circle.
PAIRS = ((0, 1, 2), (1, 2, 0), (2, 0, 1))


def vertex(ci, ri: float, cj, rj: float, ck, rk: float) -> np.ndarray:
    """The point of circles i and j by 003 section 2.2's rules (module docstring); the
    centres must differ."""
    ci, cj, ck = (np.asarray(c, float) for c in (ci, cj, ck))
    u = cj - ci
    d = math.hypot(*u)
    if d > ri + rj or d < abs(ri - rj):
        return (ci + cj) / 2.0
    a = (ri * ri - rj * rj + d * d) / (2.0 * d)
    h = math.sqrt(max(ri * ri - a * a, 0.0))
    foot = ci + a * u / d
    left = np.array([-u[1], u[0]]) / d
    p1, p2 = foot + h * left, foot - h * left
    off1, off2 = (abs(math.hypot(*(p - ck)) - rk) for p in (p1, p2))
    return p2 if off2 < off1 else p1


def vertices(centres, ranges) -> Result:
    """A, B, C of three circles (the fix ``p`` not set), or the reason there are none."""
    c = np.asarray(centres, float)[:, :2]
    r = np.asarray(ranges, float)
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r)) and np.all(r > 0.0)):
        return Result(None, reason="range_invalid")
    if any(np.array_equal(c[i], c[j]) for i, j, _ in PAIRS):
        return Result(None, reason="coincident_anchors")
    return Result(None, np.array([vertex(c[i], r[i], c[j], r[j], c[k], r[k]) for i, j, k in PAIRS]))


def centroid(centres, ranges) -> Result:
    """The centroid of A, B, C (eqs. 9-10)."""
    v = vertices(centres, ranges)
    return v if v.vertices is None else Result(v.vertices.mean(axis=0), v.vertices)


def weighted_centroid(centres, ranges) -> Result:
    """The weighted centroid of A, B, C (eqs. 11-12): weights 1/(r_i + r_j) of each vertex's
    two circles."""
    v = vertices(centres, ranges)
    if v.vertices is None:
        return v
    r = np.asarray(ranges, float)
    w = np.array([1.0 / (r[i] + r[j]) for i, j, _ in PAIRS])
    return Result(w.dot(v.vertices) / w.sum(), v.vertices)


def fix_covariance(locate, centres, ranges, sigmas, floor_m: float) -> np.ndarray:
    """The 2 x 2 covariance of the fix ``locate(centres, ranges)`` (:func:`centroid` or
    :func:`weighted_centroid`) when each range has the independent error sigma_i: J diag(sigma^2)
    J^T with J the fix's Jacobian in the ranges (central differences, 1e-6 of each range:
    the fix is piecewise smooth in them; a vertex at a midpoint does not move), plus
    ``floor_m``^2 I: the fix's own error with exact ranges (a centroid is not the point the
    ranges meet at), which the ranges' errors do not cover."""
    r = np.asarray(ranges, float)
    J = np.zeros((2, len(r)))
    for k in range(len(r)):
        h = 1e-6 * r[k]
        up, down = r.copy(), r.copy()
        up[k] += h
        down[k] -= h
        a, b = locate(centres, up).p, locate(centres, down).p
        if a is not None and b is not None:
            J[:, k] = (a - b) / (2.0 * h)
    return (J * np.asarray(sigmas, float) ** 2) @ J.T + floor_m**2 * np.eye(2)
