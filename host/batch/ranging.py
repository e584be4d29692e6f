"""host.ranging.Ranging for N seeds along a leading axis: each seed's exchanges to its
distances, TDMA cycles, WSN fixes and Tdoa products, equal to the per-seed Ranging's.

A round gives the seeds ``idx`` one exchange each (arrays: the anchor's row in the layout,
-1 for an unknown anchor; the time; the reported distance, NaN for none; the status):

* Checks and correction, as Ranging.accept and .distance: an unknown anchor or a time not
  finite rejects the exchange; an incomplete one, or a distance not in (0, max_range_m],
  gives none (NaN here); d = (reported - c_i) / f, the same float operations elementwise.
* Cycles, as host.wsn.CycleGrouper keeps each seed's open one, in arrays: the anchors that
  reported (``reported``), its first and last time, and its usable exchanges in their order
  (anchor rows, times, distances). It closes on a repeat, on an exchange more than
  ``cycle_s`` after its first, or when every anchor has reported; with three anchors or
  more (AnchorLayout's minimum) an exchange closes at most one cycle: the open one before
  it, or the one it fills. A cycle's time is the mean of its usable exchanges' times,
  summed by Python's ``sum`` as Cycle.t sums them (its rounding, whatever the version).
* Fixes: each closed cycle's through host.batch.wsn.solved (the solver's answers, the
  usual ones solved together), the last two kept as Ranging.took keeps them (``fix_t``,
  ``fix_p``, ``fix_cov``, oldest first, NaN time: none). A fix is known by its number in
  its seed (``fixes``: 1, 2, ...; 0: none), where the per-seed tracks compare Fix objects.
* Tdoa: each cycle's differences to the reference anchor (the lowest present without it)
  of the anchors whose difference is within their separation plus 4 sigma (Ranging.tdoa),
  the cycles grouped by those anchors in the cycle's order, the reference first.

The rejection counters are not kept: no estimate reads them.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navtwin.protocols.nanoloc import is_complete

from ..ranging import Ranging
from ..wsn import MIN_RANGES, AnchorLayout, tdoa_covariance
from . import wsn


class Cycles(NamedTuple):
    """The cycles one round's exchanges closed, one each of the seeds ``idx`` (k,): its
    time t (k,), the count of usable exchanges (k,), and their anchors' rows, times and
    distances (k, w), in their order (columns past the count: padding)."""
    idx: np.ndarray
    t: np.ndarray
    count: np.ndarray
    rows: np.ndarray
    times: np.ndarray
    distances: np.ndarray


class TdoaBatch(NamedTuple):
    """host.measurements.Tdoa of the seeds of one group, each seed's cycle with the same
    anchors: t (k,), z (k, m - 1), R (m - 1, m - 1) shared, the anchors' ``rows`` (m,) in
    the layout, the reference first, their lags to the filter time (k, m), and the number
    of the cycle's fix (k,; 0: none)."""
    t: np.ndarray
    z: np.ndarray
    R: np.ndarray
    rows: np.ndarray
    lags: np.ndarray
    fix: np.ndarray

    def take(self, k) -> TdoaBatch:
        return self._replace(t=self.t[k], z=self.z[k], lags=self.lags[k], fix=self.fix[k])


class BatchRanging:
    """Ranging's state for *n* seeds (module doc); ``solver`` answers every seed's cycles."""

    def __init__(self, cfg, layout: AnchorLayout, n: int) -> None:
        one = Ranging(cfg, layout)  # the per-seed ranging: its solver and range correction
        self.cfg, self.layout, self.solver = cfg, layout, one.solver
        bias, self.scale = one.correction()
        self.bias = np.array([bias.get(a, 0.0) for a in layout.ids])
        self._ids = np.array(layout.ids)
        self._ref = layout.index([cfg.reference_anchor])[0] if cfg.reference_anchor in layout else -1
        self._baselines: dict[int, np.ndarray] = {}  # reference row -> baseline to each row
        self._slack = 4.0 * math.sqrt(2.0) * cfg.range_sigma_m  # Ranging.tdoa's
        n_anchors = len(layout.ids)
        # the open cycle of each seed (count 0: none)
        self.count = np.zeros(n, np.intp)
        self.first, self.last = np.zeros(n), np.zeros(n)
        self.reported = np.zeros((n, n_anchors), bool)
        self.valid = np.zeros(n, np.intp)
        width = min(n_anchors, 8)  # grows with the cycles (a field's cycle holds ~20 of 1400)
        self.rows = np.zeros((n, width), np.intp)
        self.times, self.distances = np.zeros((n, width)), np.zeros((n, width))
        # the last two fixes, for the tracks
        self.fix_t = np.full((n, 2), np.nan)
        self.fix_p = np.zeros((n, 2, 2))
        self.fix_cov = np.zeros((n, 2, 2, 2))
        self.fixes = np.zeros(n, np.int64)

    def rows_of(self, anchors: np.ndarray) -> np.ndarray:
        """The layout rows of anchor ids (any shape); -1 for an anchor not in the layout."""
        at = np.minimum(np.searchsorted(self._ids, anchors), len(self._ids) - 1)
        return np.where(self._ids[at] == anchors, at, -1)

    def accept(self, row: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Ranging.accept: whether each exchange counts in its cycle."""
        return (row >= 0) & np.isfinite(t)

    def distance(self, row: np.ndarray, reported: np.ndarray, status: np.ndarray) -> np.ndarray:
        """Ranging.distance of accepted exchanges: the corrected distances, NaN for none."""
        ok = is_complete(status) & (0.0 < reported) & (reported <= self.cfg.max_range_m)  # NaN: no
        with np.errstate(invalid="ignore"):
            return np.where(ok, (reported - self.bias[row]) / self.scale, np.nan)

    # ---------------------------------------------------------------- cycles

    def add(self, idx: np.ndarray, row: np.ndarray, t: np.ndarray, d: np.ndarray) -> Cycles:
        """CycleGrouper.add of one accepted exchange per seed *idx* (distance d, NaN: none):
        the cycles it closes."""
        usable = ~np.isnan(d)
        if usable.any() and self.valid[idx[usable]].max() >= self.rows.shape[1]:
            self._widen()
        repeat = self.reported[idx, row] | (t - self.first[idx] > self.cfg.cycle_s)
        before = self._close(idx[(self.count[idx] > 0) & repeat])
        fresh = self.count[idx] == 0
        self.first[idx[fresh]] = t[fresh]
        self.last[idx] = t
        self.reported[idx, row] = True
        self.count[idx] += 1
        s, k = idx[usable], self.valid[idx[usable]]
        self.rows[s, k], self.times[s, k], self.distances[s, k] = row[usable], t[usable], d[usable]
        self.valid[s] += 1
        full = self._close(idx[self.count[idx] >= len(self._ids)])
        return Cycles(*(np.concatenate(pair) for pair in zip(before, full)))

    def _widen(self) -> None:
        n, w = self.rows.shape
        for name in ("rows", "times", "distances"):
            old = getattr(self, name)
            setattr(self, name, np.concatenate((old, np.zeros((n, w), old.dtype)), 1))

    def _close(self, s: np.ndarray) -> Cycles:
        """The open cycles of the seeds *s*, which are then none."""
        count = self.valid[s]
        t = np.array([sum(times[:k]) / k if k else last for times, k, last in
                      zip(self.times[s].tolist(), count.tolist(), self.last[s].tolist())])
        closed = Cycles(s, t.reshape(len(s)), count, self.rows[s], self.times[s], self.distances[s])
        self.count[s] = self.valid[s] = 0
        self.reported[s] = False
        return closed

    # ---------------------------------------------------------------- fixes

    def fix(self, c: Cycles) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """Ranging.fix of each cycle: which gave a fix, their p (k, 2) and cov (k, 2, 2),
        and why each other gave none ``{j: reason}``; the fixes kept, and numbered."""
        near = np.where(np.isnan(self.fix_t[c.idx, 1:]), np.nan, self.fix_p[c.idx, 1])
        p, cov, _, answers = wsn.solved(self.solver, c.t, c.rows, c.distances, c.count, near)
        refused = {j: a for j, a in answers.items() if isinstance(a, str)}
        for j, a in answers.items():
            if j not in refused:
                p[j], cov[j] = a.p, a.cov
        fixed = np.ones(len(c.idx), bool)
        fixed[list(refused)] = False
        s, t = c.idx[fixed], c.t[fixed]
        # Ranging.took: two fixes with one time would give no velocity; keep the newer
        self.fix_t[s, 0] = np.where(self.fix_t[s, 1] < t, self.fix_t[s, 1], np.nan)
        self.fix_p[s, 0], self.fix_cov[s, 0] = self.fix_p[s, 1], self.fix_cov[s, 1]
        self.fix_t[s, 1], self.fix_p[s, 1], self.fix_cov[s, 1] = t, p[fixed], cov[fixed]
        self.fixes[s] += 1
        return fixed, p, cov, refused

    # ---------------------------------------------------------------- tdoa

    def tdoa(self, c: Cycles, fixed: np.ndarray, t: np.ndarray) -> list[tuple[np.ndarray, TdoaBatch]]:
        """Ranging.tdoa of each cycle (*fixed*: which gave a fix) with the lags to the
        filter times *t* (k,): per group of cycles with the same anchors, their places in
        *c* and their TdoaBatch; a cycle with fewer than two differences left gives none."""
        k, w = c.rows.shape
        col = np.arange(w)
        usable = col < c.count[:, None]
        has = c.count >= MIN_RANGES  # fewer: fewer than two differences in any case
        rows = np.where(usable, c.rows, len(self._ids))
        present = (rows == self._ref).any(1)
        ref_row = np.where(present, self._ref, rows.min(1, initial=len(self._ids)))
        at = np.argmax(rows == ref_row[:, None], 1)  # the reference's place in the cycle
        j = np.flatnonzero(has)
        d_ref = c.distances[j, at[j]]
        bound = np.zeros((len(j), w))
        for r in np.unique(ref_row[j]).tolist():
            of = ref_row[j] == r
            bound[of] = self._baseline(r)[np.where(usable[j[of]], c.rows[j[of]], 0)]
        others = usable[j] & (col != at[j, None]) & \
            (np.abs(c.distances[j] - d_ref[:, None]) <= bound + self._slack)
        n_others = others.sum(1)
        j, others, d_ref, n_others = j[n_others >= 2], others[n_others >= 2], d_ref[n_others >= 2], \
            n_others[n_others >= 2]
        if not j.size:
            return []
        order = np.argsort(~others, 1, kind="stable")  # the others first, in the cycle's order
        place = np.column_stack((at[j], order))[:, :w]  # the reference, then the others
        keep = np.take_along_axis(c.rows[j], place, 1)
        keep[col[None, :] > n_others[:, None]] = -1
        sets, group = np.unique(keep, axis=0, return_inverse=True)
        group = group.ravel()
        number = np.where(fixed, self.fixes[c.idx], 0)
        out = []
        for g, anchors in enumerate(sets):
            m = int((anchors >= 0).sum())
            members = group == g
            jj, pl = j[members], place[members, :m]
            z = np.take_along_axis(c.distances[jj], pl[:, 1:], 1) - d_ref[members, None]
            lags = np.maximum(t[jj, None] - np.take_along_axis(c.times[jj], pl, 1), 0.0)
            out.append((jj, TdoaBatch(c.t[jj], z, tdoa_covariance(self.cfg.range_sigma_m, m - 1),
                                      anchors[:m].astype(np.intp), lags, number[jj])))
        return out

    def _baseline(self, ref: int) -> np.ndarray:
        """AnchorLayout.baseline of every anchor to the reference's row *ref* (by rows)."""
        b = self._baselines.get(ref)
        if b is None:
            ids = self.layout.ids
            b = self._baselines[ref] = np.array([self.layout.baseline(a, ids[ref]) for a in ids])
        return b
