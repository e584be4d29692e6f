"""host.batch.ranging: each seed's exchanges, taken a round at a time with the other seeds',
give what host.ranging.Ranging gives that seed alone, bit for bit: which exchanges count,
the corrected distances, the cycles they close, each cycle's fix or the reason for none,
and each cycle's Tdoa (its anchors, reference first, differences and lags). On the
exchanges of seeds of the shipped scenarios, some of them spoiled so that every check
rejects one (an unknown anchor, a time not finite, an outage, a distance out of range)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from navtwin.emulator.shipped import NAMES
from navtwin.host.batch.ranging import BatchRanging
from navtwin.host.measurements import Exchange, Fix, FixRefused
from navtwin.host.ranging import Ranging
from navtwin.host.wsn import AnchorLayout
from navtwin.lab import batch

from .test_batch import DURATION_S, SEEDS

LAG_S = 0.03  # the filter time's lead on an exchange: any, the same for both


def spoiled(exchanges: list, seed: int) -> list:
    """*exchanges* with every 17th (from a seed's own start) spoiled, in turn by each check."""
    out = []
    for k, r in enumerate(exchanges):
        if (k + seed) % 17 == 0:
            r = [replace(r, anchor=999), replace(r, t=float("nan")), replace(r, distance=None),
                 replace(r, status=0x8F), replace(r, distance=-1.0), replace(r, distance=1e4),
                 replace(r, distance=float("inf"))][(k // 17) % 7]
        out.append(r)
    return out


def alone(cfg, layout, exchanges: list) -> list:
    """Per exchange: None (rejected), or (distance, [(cycle t, fix or reason, tdoa), ...])."""
    ranging, out = Ranging(cfg, layout), []
    for rec in exchanges:
        if not ranging.accept(rec):
            out.append(None)
            continue
        d = ranging.distance(rec)
        closed = []
        for cycle in ranging.add(rec, d):
            fix = ranging.fix(cycle)
            closed.append((cycle.t, fix, ranging.tdoa(cycle, fix if isinstance(fix, Fix) else None,
                                                      rec.t + LAG_S)))
        out.append((d, closed))
    return out


def batched(cfg, layout, streams: list) -> list:
    """The same from BatchRanging, the seeds' k-th exchanges in round k."""
    n = len(streams)
    ranging = BatchRanging(cfg, layout, n)
    out: list = [[] for _ in range(n)]
    for k in range(max(map(len, streams))):
        idx = np.array([i for i in range(n) if k < len(streams[i])])
        recs = [streams[i][k] for i in idx]
        t = np.array([r.t for r in recs])
        row = ranging.rows_of(np.array([r.anchor for r in recs]))
        d = np.array([np.nan if r.distance is None else r.distance for r in recs])
        status = np.array([r.status for r in recs])
        ok = ranging.accept(row, t)
        for i in idx[~ok]:
            out[i].append(None)
        idx, t, row, d, status = idx[ok], t[ok], row[ok], d[ok], status[ok]
        dist = ranging.distance(row, d, status)
        c = ranging.add(idx, row, t, dist)
        fixed, p, cov, refused = ranging.fix(c)
        t_of = dict(zip(idx.tolist(), t.tolist()))
        lead = np.array([t_of[i] for i in c.idx.tolist()]) + LAG_S
        tdoa = {int(c.idx[j]): (b, g) for js, b in ranging.tdoa(c, fixed, lead) for g, j in enumerate(js)}
        for i, di in zip(idx.tolist(), dist.tolist()):
            out[i].append((di, []))
        for j, i in enumerate(c.idx.tolist()):
            answer = refused.get(j) or (c.t[j], p[j], cov[j], ranging.fixes[i])
            out[i][-1][1].append((c.t[j], answer, tdoa.get(i)))
    return out


@pytest.mark.parametrize("scenario", NAMES)
def test_the_batched_ranging_is_each_seeds_own(scenario):
    streams, cfg = [], None
    for seed in SEEDS:
        cfg, recs = batch.records(scenario, seed, filters=("wsn",), duration=DURATION_S)
        streams.append(spoiled([r for r in recs if type(r) is Exchange], seed))
    layout = AnchorLayout(cfg.anchors, cfg.tag_height)
    got = batched(cfg, layout, streams)
    cycles = tdoas = 0
    for seed, exchanges, mine in zip(SEEDS, streams, got):
        want = alone(cfg, layout, exchanges)
        assert len(mine) == len(want)
        fixes = 0
        for k, (w, g) in enumerate(zip(want, mine)):
            where = f"{scenario} seed {seed} exchange {k}"
            if w is None or g is None:
                assert w is g, where
                continue
            assert np.isnan(g[0]) if w[0] is None else g[0] == w[0], where
            assert len(w[1]) == len(g[1]), where
            for (wt, wf, wd), (gt, gf, gd) in zip(w[1], g[1]):
                cycles += 1
                assert wt == gt, where
                if isinstance(wf, FixRefused):
                    assert gf == wf.reason, where
                else:
                    fixes += 1
                    assert (wf.t, fixes) == (gf[0], gf[3]), where
                    assert np.array_equal(wf.p, gf[1]) and np.array_equal(wf.cov, gf[2]), where
                if wd.meas is None:
                    assert gd is None, where
                    continue
                tdoas += 1
                b, j = gd
                assert b.rows.tolist() == wd.meas.idx.tolist() and wd.meas.reference == wd.meas.anchors[0]
                assert np.array_equal(b.z[j], wd.z) and np.array_equal(b.R, wd.R), where
                assert b.lags[j].tolist() == list(wd.meas.lags) and b.t[j] == wd.t, where
                assert b.fix[j] == (fixes if wd.fix is not None else 0), where
    assert cycles and (tdoas or cfg.wsn_method != "tdoa")


def test_cycles_of_more_anchors_than_the_first_width_and_toa_are_each_seeds_own():
    """A field-like layout (12 anchors, a cycle of up to 12 usable exchanges: the cycle
    arrays widen), exchanges dropped at random so cycles differ in their anchor sets and
    close on a repeat or the window, and the TOA solver (each cycle by Solver.fix)."""
    cfg, _ = batch.records("office", 1, filters=("wsn",), duration=1.0)
    grid = {10 + k: (3.0 * (k % 4), 4.0 * (k // 4), 2.5) for k in range(12)}
    rng = np.random.default_rng(5)
    streams = []
    for seed in range(6):
        out, t = [], 0.0
        for _ in range(40):
            p = rng.uniform([0, 0], [9, 8])
            for a in rng.permutation(list(grid)).tolist():
                t += rng.uniform(0.002, 0.012)
                d = float(np.hypot(np.hypot(*(p - grid[a][:2])), grid[a][2]) + rng.normal(0, 0.05))
                if rng.uniform() < 0.9:
                    out.append(Exchange(t, a, d if rng.uniform() < 0.9 else None))
            t += rng.uniform(0.0, 0.15)
        streams.append(out)
    for method in ("tdoa", "toa"):
        c = replace(cfg, anchors=grid, reference_anchor=12, wsn_method=method)
        layout = AnchorLayout(c.anchors, c.tag_height)
        got = batched(c, layout, streams)
        for exchanges, mine in zip(streams, got):
            want = alone(c, layout, exchanges)
            assert len(want) == len(mine)
            assert sum(len(w[1]) for w in want) > 20
            for w, g in zip(want, mine):
                assert g[0] == w[0] or w[0] is None and np.isnan(g[0])
                for (wt, wf, wd), (gt, gf, gd) in zip(w[1], g[1], strict=True):
                    assert wt == gt
                    if isinstance(wf, FixRefused):
                        assert gf == wf.reason
                    else:
                        assert np.array_equal(wf.p, gf[1]) and np.array_equal(wf.cov, gf[2])
                    assert (gd is None) == (wd.meas is None)
                    if gd is not None:
                        b, j = gd
                        assert b.rows.tolist() == wd.meas.idx.tolist()
                        assert np.array_equal(b.z[j], wd.z) and b.lags[j].tolist() == list(wd.meas.lags)
