"""host.batch.wsn: the WSN fixes of many cycles at once are host.wsn.Solver's, cycle by
cycle, on the usual path and off it (mirror positions, too few ranges, an outlier, a
position outside the region, ranges no position fits)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from navtwin.host.batch import wsn as batch_wsn
from navtwin.host.measurements import Fix
from navtwin.host.wsn import AnchorLayout, Solver

from ..helpers import OFFICE_ANCHORS

TAG_Z = 0.3


def cycles(rng, n: int) -> list:
    """(t, anchors, ranges, near) of n cycles in the office, a mix of every case."""
    layout = AnchorLayout(OFFICE_ANCHORS, TAG_Z)
    ids = list(layout.ids)
    out = []
    for k in range(n):
        p = rng.uniform([-1.0, -1.0], [12.0, 9.0]) if k % 10 else rng.uniform(40, 60, 2)  # some outside
        anchors = ids if k % 7 else ids[:3] if k % 2 else ids[:2]  # three: mirrors; two: too few
        anchors = [a for a in rng.permutation(anchors).tolist()]  # any order: the solver sorts
        r = [math.dist((*p, TAG_Z), OFFICE_ANCHORS[a]) + rng.normal(0, 0.1) for a in anchors]
        if k % 11 == 0 and len(r) > 3:
            r[0] += 5.0  # an outlier: the residual fails (four anchors: none to drop)
        near = None if k % 3 == 0 else p + rng.normal(0, 0.3, 2)
        out.append((float(k), anchors, r, near))
    return out


@pytest.mark.parametrize("method", ["tdoa", "toa"])
def test_many_cycles_give_the_solvers_fixes(method):
    solver = Solver(AnchorLayout(OFFICE_ANCHORS, TAG_Z), 0.3, method)
    problems = cycles(np.random.default_rng(7), 400)
    got = batch_wsn.fixes(solver, problems)
    kinds = set()
    for problem, g in zip(problems, got):
        want = solver.fix(*problem)
        kinds.add(want if isinstance(want, str) else "fix")
        assert type(g) is type(want), problem
        if isinstance(want, Fix):
            assert (g.t, g.anchors, g.dropped) == (want.t, want.anchors, want.dropped)
            np.testing.assert_allclose(g.p, want.p, rtol=0, atol=1e-12)
            np.testing.assert_allclose(g.cov, want.cov, rtol=1e-12, atol=0)
            assert g.chi2 == pytest.approx(want.chi2, rel=1e-9, abs=1e-15)
        else:
            assert g == want
    # the mix reached every branch it was made for
    assert {"fix", "too_few", "outside", "residual"} <= kinds, kinds
