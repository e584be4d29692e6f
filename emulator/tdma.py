"""The anchors' TDMA schedule: which anchor ranges the tag when (``[ranging] schedule``).

The anchors share a wired network clock running fast by ``clocks.network_ppm`` (scale
s = 1 + ppm 1e-6). Cycle c starts at network time start + c x cycle + delta_c and the
exchange in slot i of it at that start + i x slot; its true time is the network time / s,
rounded to the ns, and its report's t_us is the network time (floored to the us).

delta_c is 004's sampling-time error (eq. 2.2: the measurement is taken delta_t away from
the period's tick): delta_c ~ N(0, cycle_jitter_ms^2) on the network clock, clipped to
+-(cycle - slot) / 2 so that cycle starts keep their order a slot apart, drawn from the
network's own stream ``nanoloc.cycle`` one per cycle in cycle order (:class:`CycleStarts`),
so the draws do not depend on how time is cut into blocks. 0 (the default) draws nothing.

Schedules, registered in :data:`SCHEDULES` by the ``schedule`` key's value:

``slots``     every anchor of slot_order has slot i (its place there) in every cycle.
``in-range``  at each cycle start the anchors within radio_range_m of the cycle's tag's true
              position take the cycle's slots in order of distance (nearest first, ties by
              id), at most floor(cycle / slot) of them; only they exchange. The distances are
              one vectorised computation over the field's array per block, so a cycle costs
              what its anchors in range cost, not the field's size.

Each schedule gives a block's exchanges as (anchor index, cycle, true start ns, network
time us) with a cycle in the block exactly when its exchange (slots) or its start
(in-range) falls in it; the anchors then draw their exchanges' random numbers from their
own streams in cycle order (emulator.nanoloc).
"""
from __future__ import annotations

import math

import numpy as np

from .clock import Clock
from .rng import stream


class CycleStarts:
    """delta_c, the offset of each cycle's start on the network clock (ns; module doc)."""

    def __init__(self, r, seed: int, prefix: str = "") -> None:
        self.sigma_ns = (r.cycle_jitter_ms or 0.0) * 1e6
        self.clip_ns = (r.cycle_ms - r.slot_ms) * 1e6 / 2
        self.rng = stream(seed, f"{prefix}nanoloc.cycle") if self.sigma_ns > 0 else None
        self.delta = np.zeros(0)
        self.first = 0  # the cycle of delta[0]: a block never asks for an earlier one than before

    @property
    def margin_ns(self) -> float:
        """How far a start may move: where a block looks beyond its ends for its cycles."""
        return self.clip_ns if self.rng is not None else 0.0

    def offsets(self, k: np.ndarray) -> np.ndarray:
        """delta_c (ns) of cycles *k*, drawn in cycle order as far as the largest."""
        if self.rng is None or not len(k):
            return np.zeros(len(k))
        if (need := int(k.max()) + 1 - self.first - len(self.delta)) > 0:
            new = self.sigma_ns * self.rng.standard_normal(need)
            self.delta = np.concatenate((self.delta, np.clip(new, -self.clip_ns, self.clip_ns)))
        # the cycles before this block's are done with: a long run keeps a few, not all
        drop = int(k.min()) - self.first
        assert drop >= 0, "blocks come in time order"
        self.delta, self.first = self.delta[drop:], self.first + drop
        return self.delta[k - self.first]


class Slots:
    """Every anchor its slot in every cycle: anchor i (of slot_order) at start + i x slot."""

    def __init__(self, sc, net) -> None:
        r, ppm = sc.ranging, sc.clocks.network_ppm
        self.starts = net.starts
        self.cycle_us = r.cycle_ms * 1e3
        self.clocks, us0 = [], []
        for i in range(len(net.anchors)):
            first = r.start_ms * 1e6 + i * r.slot_ms * 1e6  # network time of its first exchange
            self.clocks.append(Clock(ppm, r.cycle_ms * 1e6, round(first / (1 + ppm * 1e-6))))
            us0.append(first / 1e3)
        self.network_us0 = np.array(us0)
        self.scale = 1 + ppm * 1e-6

    def block(self, lo_ns: int, hi_ns: int):
        """(anchor index, cycle, true start ns, network us) of the exchanges starting in the block."""
        margin = math.ceil(self.starts.margin_ns / self.scale)
        ks = [c.ticks_between(lo_ns - margin, hi_ns + margin) for c in self.clocks]
        idx = np.concatenate([np.full(len(k), i) for i, k in enumerate(ks)])
        k = np.concatenate(ks)
        t0 = np.concatenate([c.tick(k) for c, k in zip(self.clocks, ks)])
        t_us = self.network_us0[idx] + k * self.cycle_us
        if margin:
            delta = self.starts.offsets(k)
            t0 = t0 + np.rint(delta / self.scale).astype(np.int64)
            t_us = t_us + delta / 1e3
            keep = (t0 >= lo_ns) & (t0 < hi_ns)
            idx, k, t0, t_us = idx[keep], k[keep], t0[keep], t_us[keep]
        return idx, k, t0, t_us


class InRange:
    """The anchors within radio range of the tag at each cycle start take its slots, nearest
    first (module doc)."""

    def __init__(self, sc, net) -> None:
        r = sc.ranging
        self.starts = net.starts
        self.tag_position = net.tag_position
        self.positions = net.positions
        self.ids = net.ids
        self.range_m = r.radio_range_m
        self.start_ns, self.cycle_ns, self.slot_ns = r.start_ms * 1e6, r.cycle_ms * 1e6, r.slot_ms * 1e6
        self.slots = math.floor(r.cycle_ms / r.slot_ms + 1e-9)
        self.scale = 1 + sc.clocks.network_ppm * 1e-6

    def block(self, lo_ns: int, hi_ns: int):
        """(anchor index, cycle, true start ns, network us) of the exchanges of the cycles
        starting in the block."""
        margin = self.starts.margin_ns
        first = max(0, math.ceil(((lo_ns - 1) * self.scale - margin - self.start_ns) / self.cycle_ns))
        last = math.floor(((hi_ns + 1) * self.scale + margin - self.start_ns) / self.cycle_ns)
        c = np.arange(first, max(first, last + 1), dtype=np.int64)
        net = self.start_ns + c * self.cycle_ns + self.starts.offsets(c)
        t = np.rint(net / self.scale).astype(np.int64)
        keep = (t >= lo_ns) & (t < hi_ns)
        c, net, t = c[keep], net[keep], t[keep]
        tag = self.tag_position(c, t)  # the cycle's tag (emulator.nanoloc: tags take turns)
        d = np.linalg.norm(tag[:, None, :] - self.positions[None, :, :], axis=2)
        idx, k, slot = [], [], []
        for row, cycle in enumerate(c.tolist()):
            near = np.flatnonzero(d[row] <= self.range_m)
            near = near[np.lexsort((self.ids[near], d[row, near]))][:self.slots]
            idx.append(near)
            k.append(np.full(len(near), cycle))
            slot.append(np.arange(len(near)))
        if not idx:
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty, empty, np.zeros(0)
        idx, k, slot = np.concatenate(idx), np.concatenate(k), np.concatenate(slot)
        at = net[np.searchsorted(c, k)] + slot * self.slot_ns  # network ns of each exchange
        return idx, k, np.rint(at / self.scale).astype(np.int64), at / 1e3


#: the ``[ranging] schedule`` values
SCHEDULES = {"slots": Slots, "in-range": InRange}
