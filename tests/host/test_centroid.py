"""003's circle points, centroid and weighted centroid (host.centroid, eqs. 9-12)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from navtwin.host import centroid as cen

TRIANGLE = np.array([[0.0, 0.0], [10.0, 0.0], [4.0, 8.0]])


def _ranges(centres, p):
    return np.linalg.norm(np.asarray(centres) - p, axis=1)


@pytest.mark.parametrize("fn", [cen.centroid, cen.weighted_centroid])
def test_exact_ranges_give_the_true_point(fn):
    rng = np.random.default_rng(1)
    for _ in range(50):
        p = rng.uniform([-5, -5], [15, 12])
        res = fn(TRIANGLE, _ranges(TRIANGLE, p))
        assert res.reason is None and np.allclose(res.p, p, atol=1e-9)
        assert np.allclose(res.vertices, p, atol=1e-9)  # every pair meets at the tag


@pytest.mark.parametrize("fn", [cen.centroid, cen.weighted_centroid])
def test_symmetric_geometry_gives_the_symmetric_answer(fn):
    # an equilateral triangle, every range the same and too long: the answer is its centre
    c = np.array([[0.0, 0.0], [6.0, 0.0], [3.0, 3.0 * math.sqrt(3)]])
    res = fn(c, [5.0, 5.0, 5.0])
    assert np.allclose(res.p, c.mean(axis=0), atol=1e-9)
    # mirror-symmetric about x = 3 with ranges to match: the fix is on the axis
    m = np.array([[0.0, 0.0], [6.0, 0.0], [3.0, 7.0]])
    res = fn(m, [4.5, 4.5, 5.5])
    assert res.p[0] == pytest.approx(3.0, abs=1e-9)


def test_no_intersection_takes_the_midpoint_of_the_centres():
    # circles 1 and 2 apart; circle 3 inside circle 1 (the paper's "no intersection" too)
    v = cen.vertex([0, 0], 2.0, [10, 0], 3.0, [5, 5], 1.0)
    assert v.tolist() == [5.0, 0.0]
    assert cen.vertex([0, 0], 9.0, [1, 0], 1.0, [5, 5], 1.0).tolist() == [0.5, 0.0]


def test_weights_follow_eqs_11_and_12():
    c, r = TRIANGLE, np.array([3.0, 9.0, 5.0])
    res = cen.weighted_centroid(c, r)
    w = np.array([1 / (3 + 9), 1 / (9 + 5), 1 / (5 + 3)])
    assert np.allclose(res.p, w @ res.vertices / w.sum())
    assert np.allclose(cen.centroid(c, r).p, res.vertices.mean(axis=0))


def _brute_vertex(ci, ri, cj, rj, ck, rk, n=400_000):
    """The paper's rule by brute force: circle i sampled at n angles, circle j crossed where
    |p - c_j| - r_j changes sign (interpolated), the crossing closest to circle k; none: the
    midpoint of the centres. Also the crossings' distances to circle k, sorted."""
    th = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    p = ci + ri * np.column_stack([np.cos(th), np.sin(th)])
    f = np.linalg.norm(p - cj, axis=1) - rj
    g = np.roll(f, -1)
    k = np.flatnonzero(np.sign(f) != np.sign(g))
    if len(k) == 0:
        return (ci + cj) / 2, np.zeros(0)
    s = f[k] / (f[k] - g[k])
    t = th[k] + s * (2 * np.pi / n)
    cross = ci + ri * np.column_stack([np.cos(t), np.sin(t)])
    off = np.abs(np.linalg.norm(cross - ck, axis=1) - rk)
    return cross[np.argmin(off)], np.sort(off)


def test_vertices_agree_with_a_brute_force_search_on_random_geometries():
    rng = np.random.default_rng(5)
    checked = 0
    while checked < 60:
        c = rng.uniform(0, 20, (3, 2))
        r = rng.uniform(1, 15, 3)
        res = cen.vertices(c, r)
        for (i, j, k), v in zip(cen.PAIRS, res.vertices):
            d = np.linalg.norm(c[j] - c[i])
            if min(abs(d - r[i] - r[j]), abs(d - abs(r[i] - r[j]))) < 0.05:
                continue  # near tangent: the crossing's position is ill-conditioned
            brute, off = _brute_vertex(c[i], r[i], c[j], r[j], c[k], r[k])
            if len(off) > 1 and off[1] - off[0] < 0.05:
                continue  # a near tie for the closer point
            assert np.allclose(v, brute, atol=1e-3), (c, r, i, j)
            checked += 1


@pytest.mark.parametrize("centres, ranges, reason", [
    ([[0, 0], [0, 0], [5, 5]], [1.0, 2.0, 3.0], "coincident_anchors"),
    ([[0, 0], [4, 0], [5, 5]], [0.0, 2.0, 3.0], "range_invalid"),
    ([[0, 0], [4, 0], [5, 5]], [0.0, 0.0, 0.0], "range_invalid"),
    ([[0, 0], [4, 0], [5, 5]], [1.0, float("nan"), 3.0], "range_invalid"),
    ([[0, 0], [4, 0], [5, float("inf")]], [1.0, 2.0, 3.0], "range_invalid"),
    ([[0, 0], [4, 0], [5, 5]], [-1.0, 2.0, 3.0], "range_invalid"),
])
@pytest.mark.parametrize("fn", [cen.centroid, cen.weighted_centroid])
def test_degenerate_input_gives_no_fix_and_a_reason(fn, centres, ranges, reason):
    res = fn(centres, ranges)
    assert res.p is None and res.reason == reason


@pytest.mark.parametrize("fn", [cen.centroid, cen.weighted_centroid])
def test_fix_covariance_is_the_spread_of_the_fix_under_small_range_errors(fn):
    """J diag(sigma^2) J^T against the fix's sample covariance over range errors drawn with
    those sigmas (small: the fix stays in one piece of its piecewise-smooth map)."""
    rng = np.random.default_rng(5)
    p = np.array([4.5, 3.0])
    r = _ranges(TRIANGLE, p)
    sigma = np.array([0.01, 0.02, 0.015])
    draws = np.array([fn(TRIANGLE, r + rng.normal(0.0, sigma)).p for _ in range(20_000)])
    cov = cen.fix_covariance(fn, TRIANGLE, r, sigma, 0.0)
    assert np.allclose(cov, np.cov(draws.T), rtol=0.05, atol=0.03 * np.abs(cov).max())
    floor = cen.fix_covariance(fn, TRIANGLE, r, sigma, 2.0) - cov
    assert np.allclose(floor, 4.0 * np.eye(2))
