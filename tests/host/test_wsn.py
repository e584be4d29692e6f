"""WSN positioning: exact on exact ranges, CRLB-efficient on noisy ones, robust to one outlier."""
from __future__ import annotations

import math

import numpy as np
import pytest

from navtwin.host.measurements import Fix
from navtwin.host.wsn import (AnchorLayout, CycleGrouper, Solver, tdoa_closed_form, tdoa_covariance,
                              tdoa_whitening, toa_linear)

from ..helpers import CORRIDOR_ANCHORS, OFFICE_ANCHORS

PLANAR = AnchorLayout(OFFICE_ANCHORS, tag_height=0.0)
# anchors on the walls at 2.4 m, tag on the car at 0.3 m: 3-D ranges, 2-D position
HEIGHTS = {1: 2.4, 2: 2.2, 3: 2.4, 4: 2.3}
RAISED = AnchorLayout({k: (x, y, HEIGHTS[k]) for k, (x, y, _) in OFFICE_ANCHORS.items()}, tag_height=0.3)
# inside, on the room's symmetry axes (where Chan-Ho is singular), near an anchor, outside the hull
POINTS = [(6.05, 3.5), (6.05, 2.2), (3.0, 3.5), (2.0, 2.0), (9.5, 5.0), (11.5, 0.9)]


def exact_ranges(layout, p):
    return layout.ranges(np.asarray(p, float)[None], np.arange(4))


def crlb_toa(layout, p, sigma):
    return sigma * layout.hdop(np.asarray(p, float))


def crlb_tdoa(layout, p, sigma):
    _, u = layout.geometry(np.asarray(p, float), np.arange(4))
    H = u[1:] - u[0]
    return math.sqrt(np.trace(np.linalg.inv(H.T @ np.linalg.inv(tdoa_covariance(sigma, 3)) @ H)))


def test_at_an_anchor_of_the_tags_height_a_range_has_the_subgradient_zero():
    """A position on an anchor of the tag's height (r = 0): the other ranges' directions as
    anywhere, that anchor's d r / d p zero (it was 0/0, NaN, in a filter's Jacobian); on a
    raised anchor (r = its height above the tag) the direction is the ordinary one, 0."""
    a = np.asarray(OFFICE_ANCHORS[min(OFFICE_ANCHORS)][:2], float)
    near = a + 1e-9
    r, u = PLANAR.geometry(a, np.arange(4))
    r_near, u_near = PLANAR.geometry(near, np.arange(4))
    assert r[0] == 0.0 and np.array_equal(u[0], [0.0, 0.0]) and np.isfinite(u).all()
    np.testing.assert_allclose(u[1:], u_near[1:], atol=1e-9)
    assert np.linalg.norm(u_near[0]) == pytest.approx(1.0)  # a unit vector anywhere else
    r, u = RAISED.geometry(a, np.arange(4))
    assert r[0] > 0 and np.array_equal(u[0], [0.0, 0.0])


@pytest.mark.parametrize("layout", [PLANAR, RAISED], ids=["planar", "raised"])
@pytest.mark.parametrize("p", POINTS)
def test_closed_forms_are_exact_on_exact_ranges(layout, p):
    r = exact_ranges(layout, p)
    idx = np.arange(4)
    np.testing.assert_allclose(toa_linear(layout, idx, r), p, atol=1e-9)
    (start,) = tdoa_closed_form(layout, idx[1:], r[1:] - r[0], 0, tdoa_whitening(0.3, 3))
    np.testing.assert_allclose(start, p, atol=1e-7)


@pytest.mark.parametrize("method", ["toa", "tdoa"])
@pytest.mark.parametrize("layout", [PLANAR, RAISED], ids=["planar", "raised"])
@pytest.mark.parametrize("p", POINTS)
def test_gauss_newton_fix_is_exact_on_exact_ranges(method, layout, p):
    fix = Solver(layout, 0.3, method).fix(1.0, [1, 2, 3, 4], exact_ranges(layout, p))
    assert isinstance(fix, Fix)
    np.testing.assert_allclose(fix.p, p, atol=1e-9)
    assert fix.chi2 < 1e-12 and fix.anchors == (1, 2, 3, 4) and fix.dropped == ()


def test_fix_covariance_is_the_crlb():
    p = (3.0, 2.5)
    fix = Solver(RAISED, 0.3).fix(0.0, [4, 2, 3, 1], exact_ranges(RAISED, p)[[3, 1, 2, 0]])
    np.testing.assert_allclose(fix.p, p, atol=1e-9)  # the report order does not matter
    assert math.sqrt(np.trace(fix.cov)) == pytest.approx(crlb_toa(RAISED, p, 0.3), rel=1e-9)


@pytest.mark.parametrize("method,crlb", [("toa", crlb_toa), ("tdoa", crlb_tdoa)])
@pytest.mark.parametrize("p", [(6.05, 3.5), (3.0, 2.5), (9.5, 5.0)])
def test_noisy_rmse_is_close_to_the_crlb(method, crlb, p):
    """fusion-facts 4.1: RMSE >= sigma * HDOP, and Gauss-Newton attains it (within 10 %)."""
    rng = np.random.default_rng(2024)
    sigma, n = 0.3, 3000
    solver = Solver(RAISED, sigma, method)
    r0 = exact_ranges(RAISED, p)
    err = []
    for noise in rng.normal(0.0, sigma, (n, 4)):
        fix = solver.fix(0.0, [1, 2, 3, 4], r0 + noise)
        err.append(fix.p - p)
    rmse = math.sqrt(np.mean(np.sum(np.square(err), axis=1)))
    bound = crlb(RAISED, p, sigma)
    assert bound * 0.9 < rmse < bound * 1.1, (rmse, bound)


@pytest.mark.parametrize("method", ["toa", "tdoa"])
def test_one_outlier_is_dropped_when_the_rest_can_vouch_for_it(method):
    """A 3 m NLOS-like error on anchor 3: the gate sees it; a subset without it wins when
    that subset keeps two degrees of freedom (TOA 5 anchors, TDOA 6). With one fewer
    anchor there is no fix: one degree of freedom cannot tell which range is wrong."""
    p = (4.0, 3.0)
    extra = {5: (6.05, 0.5, 0.0), 6: (6.05, 6.5, 0.0)}
    enough = 5 if method == "toa" else 6
    ids = list(range(1, enough + 1))
    layout = AnchorLayout({**OFFICE_ANCHORS, **extra}, 0.0)
    r = layout.ranges(np.array(p)[None], layout.index(ids))
    r[2] += 3.0  # anchor 3
    solver = Solver(layout, 0.05, method)
    fix = solver.fix(0.0, ids, r)
    assert fix.dropped == (3,) and 3 not in fix.anchors
    np.testing.assert_allclose(fix.p, p, atol=1e-6)
    assert solver.fix(0.0, ids[:-1], r[:-1]) == "residual"


def test_fixes_outside_the_plausible_region_are_refused():
    solver = Solver(PLANAR, 0.3, margin_m=1.0)
    assert isinstance(solver.fix(0.0, [1, 2, 3, 4], exact_ranges(PLANAR, (11.5, 0.9))), Fix)
    assert solver.fix(0.0, [1, 2, 3, 4], exact_ranges(PLANAR, (13.0, 3.0))) == "outside"
    assert isinstance(Solver(PLANAR, 0.3, margin_m=None).fix(0.0, [1, 2, 3, 4],
                                                            exact_ranges(PLANAR, (13.0, 3.0))), Fix)


def test_too_few_ranges_give_no_fix():
    assert Solver(PLANAR, 0.3).fix(0.0, [1, 2], [5.0, 6.0]) == "too_few"
    assert isinstance(Solver(PLANAR, 0.3, "tdoa").fix(0.0, [1, 2, 3], exact_ranges(PLANAR, (5, 3))[:3]), Fix)


def test_cycles_close_on_all_anchors_a_repeat_or_the_window():
    g = CycleGrouper(4, window_s=0.1)
    assert g.add(0.000, 1, 5.0) == [] and g.add(0.025, 2, None) == [] and g.add(0.050, 3, 4.0) == []
    (full,) = g.add(0.075, 4, 3.0)  # all four reported (one failed)
    assert full.anchors == [1, 2, 3, 4] and full.valid_anchors == [1, 3, 4]
    assert full.t == pytest.approx((0.0 + 0.05 + 0.075) / 3)
    g.add(0.100, 1, 5.0)
    (repeat,) = g.add(0.200, 1, 5.1)  # anchors 2..4 silent: anchor 1 again closes it
    assert repeat.anchors == [1]
    (late,) = g.add(0.400, 2, 5.2)  # more than the window after the open cycle's start
    assert late.anchors == [1] and late.times == [0.2]


# the corridor's anchors while anchor 2 is silent (corridor-outage): three, nearly in a line
CORRIDOR = AnchorLayout({k: CORRIDOR_ANCHORS[k] for k in (1, 3, 4)})


def ulp_variants(r):
    """The ranges with one of them moved by 1-3 ulps: the rounding noise another CPU's BLAS
    kernels give."""
    for j in range(len(r)):
        for k in (-3, -2, -1, 1, 2, 3):
            v = r.copy()
            v[j] += k * np.spacing(v[j])
            yield v


def test_tdoa_mirror_positions_are_told_apart_by_geometry_not_by_rounding():
    """Three anchors, two range differences, two unknowns: the tag's position and its mirror
    both fit exactly, so their misfits differ by rounding noise only (the old choice by the
    smaller misfit flipped with the BLAS kernel: corridor-outage's fixes differed by metres
    on AVX-512). The plausible region decides; where both are in it, the previous fix."""
    solver = Solver(CORRIDOR, 0.4, "tdoa")
    p = np.array([-9.15, 0.21])  # mirror near (-9.8, 4.5), beyond the region
    for r in ulp_variants(CORRIDOR.ranges(p[None], np.arange(3))):
        fix = solver.fix(18.15, [1, 3, 4], r)
        assert isinstance(fix, Fix)
        np.testing.assert_allclose(fix.p, p, atol=1e-6)
    p, mirror = np.array([-11.22, 0.0]), np.array([-11.83, 2.98])  # both in the region
    for r in ulp_variants(CORRIDOR.ranges(p[None], np.arange(3))):
        assert solver.fix(21.05, [1, 3, 4], r) == "geometry"  # nothing to tell them apart
        near_tag = solver.fix(21.05, [1, 3, 4], r, near=(-11.1, 0.1))
        np.testing.assert_allclose(near_tag.p, p, atol=1e-6)
        near_mirror = solver.fix(21.05, [1, 3, 4], r, near=(-11.7, 2.8))
        np.testing.assert_allclose(near_mirror.p, mirror, atol=0.01)


def test_tdoa_ranges_no_position_fits_give_no_fix_whatever_the_rounding():
    """corridor-outage seed 3 at 19.25 s: the three ranges' hyperbolae do not meet, so
    Gauss-Newton hops about the singular closest approach for all its iterations and its
    last iterate (the old fix) depended on the last bit of every product."""
    solver = Solver(CORRIDOR, 0.4, "tdoa")
    r = np.array([11.434323780532718, 2.1468722851764577, 10.361092130207716])
    fixes = [solver.fix(19.25, [1, 3, 4], v) for v in [r, *ulp_variants(r)]]
    assert {f if isinstance(f, str) else tuple(f.p.round(6)) for f in fixes} == {"geometry"}
