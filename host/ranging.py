"""The estimator's ranging part: exchanges from their reports to the WSN's products
(docs/filters.md).

* Checks and correction. An exchange of an unknown anchor, or at a non-finite time, is
  rejected; one that did not complete (timeout: ``outage``, else ``incomplete``) or whose
  distance is not in (0, max_range_m] gives no distance but still counts in its cycle; a
  distance is corrected as d = (reported - c_i) / f (001's calibration, else
  ``range_bias_m`` and ``range_scale``).
* Range: each corrected distance as a measurement, sigma = ``range_sigma_m``.
* Cycles: the exchanges grouped into TDMA cycles (host.wsn.CycleGrouper, ``cycle_s``).
* Fixes: each closed cycle's WSN fix (host.wsn.Solver, ``wsn_method``), or FixRefused.
* Tdoa: each cycle's range differences to the reference anchor (000 eqs. 12-13).
"""
from __future__ import annotations

import math
from collections import Counter

import numpy as np

from navtwin.protocols.nanoloc import STATUS_TIMEOUT, is_complete

from .filters import Ranges
from .measurements import Exchange, Fix, FixRefused, Range, Tdoa
from .wsn import AnchorLayout, Cycle, CycleGrouper, Solver, tdoa_covariance


class Ranging:
    """Turns exchanges into distances, TDMA cycles, WSN fixes and Range and Tdoa products.

    Owns the range correction (f and c_i), the open cycle (``grouper``), the solver, the
    last two fixes (``fixes``, oldest first, of distinct times), the count of exchanges
    (``exchanges``) and the rejections by reason (``rejections``)."""

    def __init__(self, cfg, layout: AnchorLayout) -> None:
        self.cfg = cfg
        self.layout = layout
        self.solver = Solver(layout, cfg.range_sigma_m, cfg.wsn_method, cfg.reference_anchor,
                             cfg.gate_probability, cfg.fix_margin_m)
        self.grouper = CycleGrouper(len(layout.ids), cfg.cycle_s)
        self.fixes: list[Fix] = []
        cal = cfg.calibration
        self._scale = cal.scale if cal else cfg.range_scale
        self._bias = dict(cal.bias) if cal else {int(a): float(c) for a, c in cfg.range_bias_m.items()}
        self.exchanges = 0
        self.rejections: Counter = Counter()

    def correction(self) -> tuple[dict[int, float], float]:
        """The range correction d = (reported - c_i) / f: c_i by anchor id (absent: 0) and f
        (host.batch.ranging applies it to many seeds' exchanges at once)."""
        return dict(self._bias), self._scale

    def accept(self, rec: Exchange) -> bool:
        """Whether the exchange counts in its cycle (else rejected whole, counted)."""
        self.exchanges += 1
        if rec.anchor not in self.layout:
            self.rejections["unknown_anchor"] += 1
            return False
        if not math.isfinite(rec.t):
            self.rejections["range_implausible"] += 1
            return False
        return True

    def distance(self, rec: Exchange) -> float | None:
        """The exchange's corrected distance (m), or None (counted by reason)."""
        distance_m, status = rec.distance, rec.status
        if distance_m is None or not is_complete(status):
            self.rejections["outage" if status & STATUS_TIMEOUT else "incomplete"] += 1
            return None
        if not (math.isfinite(distance_m) and 0.0 < distance_m <= self.cfg.max_range_m):
            self.rejections["range_implausible"] += 1
            return None
        return (float(distance_m) - self._bias.get(rec.anchor, 0.0)) / self._scale

    def range(self, rec: Exchange, d: float, t: float) -> Range:
        """The Range product of distance d, measured at rec.t, for the filter time t."""
        return Range(rec.t, np.array([d]), np.array([[self.cfg.range_sigma_m**2]]),
                     Ranges(self.layout, (rec.anchor,), (max(t - rec.t, 0.0),)))

    def add(self, rec: Exchange, d: float | None) -> list[Cycle]:
        """The cycles that the exchange (with distance d, None: none) closes."""
        return self.grouper.add(rec.t, rec.anchor, d)

    def fix(self, cycle: Cycle) -> Fix | FixRefused:
        """The cycle's fix (kept in ``fixes``), or why the solver refused one."""
        return self.took(cycle, self.solver.fix(*self.problem(cycle)))

    def problem(self, cycle: Cycle) -> tuple:
        """What the solver is asked of *cycle*: (t, anchors, ranges, near)."""
        # the previous fix tells TDOA mirror positions apart (three anchors: both fit exactly)
        near = self.fixes[-1].p if self.fixes else None
        return cycle.t, cycle.valid_anchors, cycle.distances, near

    def took(self, cycle: Cycle, fix: Fix | str) -> Fix | FixRefused:
        """The solver's answer to :meth:`problem` (host.batch.wsn answers many at once): a
        fix kept in ``fixes``, or why there is none."""
        if isinstance(fix, str):
            return FixRefused(cycle.t, fix)
        # two fixes with one time would give no velocity: keep the newer
        older = [f for f in self.fixes[-1:] if f.t < fix.t]
        self.fixes = [*older, fix]
        return fix

    def tdoa(self, cycle: Cycle, fix: Fix | None, t: float) -> Tdoa:
        """The cycle's range differences to the reference anchor (000 eqs. 12-13), R =
        sigma^2 (I + 11^T), with their lags to the filter time t."""
        r = dict(zip(cycle.valid_anchors, cycle.distances))
        t_of = dict(zip(cycle.valid_anchors, cycle.valid_times))
        ref = self.cfg.reference_anchor if self.cfg.reference_anchor in r else min(r, default=None)
        # |r_i - r_ref| cannot exceed the anchors' separation (triangle inequality), give or
        # take 4 sigma of the difference's noise (it is tight on the line through the two)
        slack = 4.0 * math.sqrt(2.0) * self.cfg.range_sigma_m
        others = []
        implausible = 0
        for a in r:
            if a != ref and abs(r[a] - r[ref]) <= self.layout.baseline(a, ref) + slack:
                others.append(a)
            elif a != ref:
                implausible += 1
        if len(others) < 2:
            return Tdoa(cycle.t, implausible, fix=fix)
        keep = [ref, *others]
        z = np.array([r[a] - r[ref] for a in others])
        meas = Ranges(self.layout, keep, [max(t - t_of[a], 0.0) for a in keep], reference=ref)
        R = tdoa_covariance(self.cfg.range_sigma_m, len(others))
        return Tdoa(cycle.t, implausible, z, R, meas, fix)

    def restart(self) -> None:
        """A device restarted: no cycle spans it, and the fixes before it are history."""
        self.grouper = CycleGrouper(len(self.layout.ids), self.cfg.cycle_s)
        self.fixes = []
