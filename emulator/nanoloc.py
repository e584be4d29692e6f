"""nanoLOC ranging: the anchors, the tags, the four-timestamp exchange, the gateway.

Tags. A network ranges one tag or, when several vehicles share it (``[ranging] network =
"shared"``), their tags in turn: cycle c is the cycle of tag c mod T (T tags, vehicle 1's
first), so each tag is ranged every T-th cycle and its rate falls as tags are added; a
vehicle with a network of its own (``"per-vehicle"``) has the anchors' draws and cycle
starts from streams named under "vehicle<n>." (the anchors' multipath field is the
room's, the same in every network).

Schedule (emulator.tdma). The anchors share a wired network clock (ppm
``clocks.network_ppm``). Cycle c starts at network time start + c x cycle (+ delta_c, 004
eq. 2.2's sampling-time error, with ``cycle_jitter_ms``); the anchor in slot i starts its
exchange with the tag at cycle start + i x slot. With ``schedule = "slots"`` anchor i of
slot_order has slot i in every cycle; with ``"in-range"`` the anchors within radio_range_m
of the tag at the cycle start take the slots, nearest first, at most floor(cycle / slot):
a field of hundreds of anchors (``[[anchor_grids]]``) costs per cycle what its anchors in
range cost. Each exchange is timed from the true geometry at its own moments, so the
vehicle moves between the slots of a cycle.

Exchange (true times, node clocks running fast by e_A for the anchor, e_T for the tag)::

    leg 1  anchor sends; the tag detects the packet after tof1 + d1 and replies after
           P_T = tag_reply / (1 + e_T) + jitter; the anchor detects the reply after tof2 + d2
           tau1 = (tof1 + d1 + P_T + tof2 + d2)(1 + e_A)      tau2 = P_T (1 + e_T)
    gap    leg_gap / (1 + e_T)
    leg 2  the tag sends; the anchor replies after P_A = anchor_reply / (1 + e_A) + jitter
           tau3 = (tof3 + d3 + P_A + tof4 + d4)(1 + e_T)      tau4 = P_A (1 + e_A)

tof_k = |tag(t_k) - anchor| / c (3-D, at the moment of leg k's transmission). The detection
errors d_k carry 001's range model d~ = f d + c_i + eps_NLOS + D (001 eq. 13)::

    d_k = (f - 1) tof_k + (c_i + eps) / c + n_k,   n_k ~ N(0, (2 sigma(d_k) / c)^2),
    sigma(d) = sigma0 + sigma_per_m d,   eps = the anchor's multipath error (emulator.multipath,
    when [ranging.multipath] is enabled) + Exp(mean bias_m) inside an ``nlos`` fault

so c (tau1 - tau2 + tau3 - tau4) / 4 = f d + c_i + eps + D with D ~ N(0, sigma(d)^2) plus the
clock terms of wire-formats.md section 3: (1 + (e_A + e_T)/2) on the time of flight and
(e_A - e_T)(P_T - P_A)/4, which cancel to first order, while the single-sided c (tau1 - tau2)/2
keeps c (e_A - e_T) P_T / 2. The taus are rounded to whole picoseconds. The emulator never
computes the distance itself.

Anchor-to-anchor exchanges. With ``anchor_exchange_every_cycles`` = K > 0, in cycles 0, K,
2K, ... the anchor in slot i ranges, in place of the tag, the anchor in slot
(i + 1 + s mod (m - 1)) mod m (s = k // K; m anchors), so m - 1 such cycles cover every
ordered pair. The
exchange is the same physics with the other anchor's position and crystal in the tag's
place; its report carries that anchor's id in the tag field and its RSSI is what the ranging
anchor hears of it: 003's eqs. 3-4 fit each anchor's path-loss parameters to these readings.
The draws are the anchor's per-cycle ones as for the tag, so these exchanges move no other draw.

An exchange times out (status 0x40, zero taus, RSSI -128 dBm) inside an ``anchor_outage``
fault or at random with probability timeout_prob; the anchor reports it timeout_ms after it
started. An exchange whose anchor is farther from the tag than ``radio_range_m`` (when set)
at its first leg is not reported at all: the gateway writes only the exchanges the radio
range allows (its random draws are made all the same, so the range changes no other
exchange). RSSI at the anchor: RSSI(1 m) - 10 n lg d + N(0, shadowing^2) - NLOS attenuation
(003 eq. 1), in whole dBm. The anchor has its result result_us after the exchange; the
gateway receives it latency_us later and writes one 32-byte report per exchange, in order,
on its serial line (wire-formats.md section 3); the 34-byte wide report (type 02) when some
anchor or tag id exceeds 254.

A sweep's seeds of one scenario make each block's exchanges together
(:meth:`NanolocNetwork.reports_together`), every network's reports those it makes alone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.protocols.nanoloc import (FRAME_SIZE, NARROW_IDS, SPEED_OF_LIGHT, STATUS_COMPLETE,
                                      STATUS_TIMEOUT, STATUS_VALUE_ERROR, WIDE_FRAME_SIZE, build_reports)
from navtwin.protocols.fast import frames_of
from navtwin.protocols.serial import char_ns

from .alike import alike
from .clock import serial_queue
from .rng import stream
from .faults import acting_on
from .multipath import Multipath
from .tdma import SCHEDULES, CycleStarts

PS_PER_S = 1e12
RSSI_NONE = -128  # dBm reported with a timeout: nothing was received
U32 = 0xFFFFFFFF


@dataclass(slots=True)
class ExchangeEffects:
    """What anchor faults (emulator.faults, ACTS_ON "anchor") change in a block's exchanges,
    one entry per exchange; ``act`` changes the arrays in place."""

    timeout: np.ndarray  # bool: the exchange times out
    bias_m: np.ndarray  # extra range bias (on top of the anchor's range_bias_m)
    attenuation_db: np.ndarray  # extra path loss on the RSSI
    exponential: np.ndarray  # a standard exponential draw per exchange (the NLOS bias)
    uniform: np.ndarray  # the uniform draw per exchange (below timeout_prob: a random timeout)
    value_error: np.ndarray  # bool: the gateway flags the exchange (status 0x80)


class Anchor:
    """One anchor: its crystal, range bias, faults and random stream (made at its first
    exchange: a field of 1400 anchors starts without 1400 generators)."""

    def __init__(self, sc, spec, seed: int, prefix: str = "") -> None:
        r = sc.ranging
        self.stream_name = f"{prefix}nanoloc.anchor.{spec.id}"
        self.id = spec.id
        self.position = sc.anchor_position(spec)
        self.e = spec.ppm * 1e-6
        self.bias = spec.range_bias_m
        self.faults = tuple(acting_on(sc.faults, "anchor", anchor=spec.id))
        self.seed = seed
        self._rng = None
        self.multipath = Multipath(r.multipath, spec.id, seed) if r.multipath.enabled else None

    def draw(self, normal: np.ndarray, uniform: np.ndarray, exponential: np.ndarray) -> None:
        """The random draws of its next exchanges, one a row, written into contiguous
        *normal* (n, 7): jitter T, jitter A, n1..n4, shadowing; *uniform* (n,): the timeout;
        *exponential* (n,): the NLOS bias (in place: a block has a few per anchor, and the
        arrays the generator would make cost more than the draws)."""
        if self._rng is None:
            self._rng = stream(self.seed, self.stream_name)
        self._rng.standard_normal(out=normal)
        self._rng.random(out=uniform)
        self._rng.standard_exponential(out=exponential)


class NanolocNetwork:
    """All anchors, the tags (each with its vehicle's trajectory) and the gateway's serial
    line; *prefix* names the network's streams (module doc)."""

    def __init__(self, sc, tags, trajectories, seed: int, prefix: str = "") -> None:
        by_id = {a.id: a for a in sc.all_anchors}
        order = sc.slot_order if sc.ranging.tdma == "slots" else [a.id for a in sc.all_anchors]
        self.anchors = [Anchor(sc, by_id[a], seed, prefix) for a in order]
        # the anchors' constants as arrays, indexed as self.anchors: a block never loops over them
        self.ids = np.array([a.id for a in self.anchors])
        self.positions = np.array([a.position for a in self.anchors])
        self.e_a = np.array([a.e for a in self.anchors])
        self.bias = np.array([a.bias for a in self.anchors])
        self.r = sc.ranging
        self.e_t = np.array([tag.ppm * 1e-6 for tag in tags])
        self.tags = np.array([tag.id for tag in tags])
        self.trajectories = tuple(trajectories)
        m, every = len(self.anchors), sc.ranging.anchor_exchange_every_cycles
        self.anchor_every = every if m > 1 else 0  # a lone anchor has no one to range
        self.starts = CycleStarts(sc.ranging, seed, prefix)
        self.schedule = SCHEDULES[sc.ranging.tdma](sc, self)
        self.latency_ns = round(sc.gateway.latency_us * 1e3)
        # ids past type 01's byte: every report is the wide type 02 (protocols.nanoloc)
        self.wide = max(max(by_id), int(self.tags.max())) > NARROW_IDS[1]
        self.report_ns = round((WIDE_FRAME_SIZE if self.wide else FRAME_SIZE) * char_ns(sc.gateway.baud))
        self.busy_until = 0
        self.seq = 0
        #: all a block's arithmetic and schedule take besides the draws and the anchors'
        #: faults and multipath: networks of one key (a sweep's seeds of one scenario) make
        #: their blocks together (:meth:`reports_together`)
        self.key = (self.r, sc.clocks.network_ppm, tuple(t.key for t in self.trajectories),
                    self.anchor_every, self.latency_ns, self.report_ns, self.wide,
                    *(a.tobytes() for a in (self.tags, self.e_t, self.ids, self.positions, self.e_a,
                                            self.bias)))

    def tag_position(self, k: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
        """(n, 3) true positions at *t_ns* of the tags of cycles *k* (module doc), in metres."""
        if len(self.trajectories) == 1:
            return self.trajectories[0].position(t_ns)
        which = k % len(self.trajectories)
        out = np.empty((len(t_ns), 3))
        for i in np.unique(which).tolist():
            mine = which == i
            out[mine] = self.trajectories[i].position(t_ns[mine])
        return out

    def reports(self, lo_ns: int, hi_ns: int) -> tuple[np.ndarray, list[bytes], dict]:
        """Write start times and bytes of the reports of the exchanges starting in the block,
        and the ledger marks of the reports a fault changed (by index)."""
        return self.reports_together([self], lo_ns, hi_ns)[0]

    @staticmethod
    def reports_together(networks: list[NanolocNetwork], lo_ns: int,
                         hi_ns: int) -> list[tuple[np.ndarray, list[bytes], dict]]:
        """:meth:`reports` of the block [lo_ns, hi_ns) for each of *networks*, each network's
        reports and state as it alone would leave them. The networks of equal ``key`` (a
        sweep's seeds of one scenario) are run along a seed axis: the blocks of 1 s hold a
        few dozen exchanges, so one numpy call over all the seeds' exchanges costs what one
        seed's did. Per seed still: the schedule's block when it has cycle jitter (its own
        cycle starts; without, the schedule draws nothing and one block serves all), each
        anchor's draws (its own stream, in its cycle order), the anchor faults and multipath
        of its anchors (a loop over the anchors that have them), the gateway's serial line
        and counter, the ledger marks."""
        out = [None] * len(networks)
        for members in alike([net.key for net in networks]):
            for i, made in zip(members, _reports([networks[i] for i in members], lo_ns, hi_ns)):
                out[i] = made
        return out


def _reports(nets: list[NanolocNetwork], lo_ns: int, hi_ns: int) -> list[tuple]:
    """reports_together of networks of one key: each one's (write starts, frames, marks)."""
    x, marks, bounds = _exchanges(nets, lo_ns, hi_ns)
    first, n = nets[0], len(x["ready_ns"])
    start, seq = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    for net, a, b in zip(nets, bounds, bounds[1:]):
        start[a:b], end = serial_queue(x["ready_ns"][a:b], np.full(b - a, first.report_ns), net.busy_until)
        if b > a:
            net.busy_until = int(end[-1])
        seq[a:b] = net.seq + np.arange(b - a)
        net.seq += b - a
    frames = frames_of(build_reports(seq=seq, t_us=x["t_us"], anchor=x["anchor"], tag=x["tag"],
                                     status=x["status"], rssi=x["rssi"], tau=x["tau"], wide=first.wide))
    return [(start[a:b], frames[a:b], mine) for a, b, mine in zip(bounds, bounds[1:], marks)]


def _exchanges(nets: list[NanolocNetwork], lo_ns: int, hi_ns: int) -> tuple[dict, list[dict], list[int]]:
    """The exchanges starting in [lo_ns, hi_ns) of networks of one key, network after
    network, each network's in start order: anchor, start, t_us, status, rssi, taus (ps) and
    when the gateway has the result; with each network's ledger marks (by its report's index)
    and where each network's exchanges begin (and the last ends)."""
    first = nets[0]  # the anchors' and tags' constants and the ranging keys are all the same
    r = first.r
    # without cycle jitter the schedule draws nothing: the key's networks have one block
    blocks = [first.schedule.block(lo_ns, hi_ns)] * len(nets) if first.starts.rng is None else \
        [net.schedule.block(lo_ns, hi_ns) for net in nets]
    idx, k, t0, network_us = (np.concatenate(col) for col in zip(*blocks))
    m = len(k)
    seg = np.repeat(np.arange(len(nets)), [len(b[1]) for b in blocks])  # each exchange's network
    # each exchange's anchor among all the networks' anchors, network after network
    anchors = [a for net in nets for a in net.anchors]
    g = seg * len(first.anchors) + idx
    # each anchor's draws in its cycle order, from its own stream (emulator.tdma)
    by_anchor = np.argsort(g, kind="stable")
    present, counts = np.unique(g, return_counts=True)
    present = present.tolist()  # the anchors of the block's exchanges: no others act
    normal, uniform, exponential = np.empty((m, 7)), np.empty(m), np.empty(m)
    ends = np.cumsum(counts).tolist()
    for i, a, b in zip(present, [0] + ends, ends):
        anchors[i].draw(normal[a:b], uniform[a:b], exponential[a:b])
    z = np.empty((m, 9))
    z[by_anchor, :7], z[by_anchor, 7], z[by_anchor, 8] = normal, uniform, exponential
    e_a = first.e_a[idx]
    # the far end of each exchange: the tag, or another anchor (module doc)
    peer = np.full(m, -1)
    if first.anchor_every:
        n = len(first.anchors)
        among = k % first.anchor_every == 0
        peer[among] = (idx[among] + 1 + (k[among] // first.anchor_every) % (n - 1)) % n
    peered = peer >= 0
    tag_of = k % len(first.tags)  # the cycle's tag
    e_t = np.where(peered, first.e_a[peer], first.e_t[tag_of])
    p_t = r.tag_reply_us * 1e-6 / (1 + e_t) + r.reply_jitter_ns * 1e-9 * z[:, 0]
    p_a = r.anchor_reply_us * 1e-6 / (1 + e_a) + r.reply_jitter_ns * 1e-9 * z[:, 1]
    gap = r.leg_gap_us * 1e-6 / (1 + e_t)
    # transmission moments of the four legs (the nanoseconds of flight do not matter here)
    offsets = np.column_stack((np.zeros(m), p_t, p_t + gap, p_t + gap + p_a))
    when = t0[:, None] + np.rint(offsets * 1e9).astype(np.int64)
    where = first.positions[idx]
    tag = first.tag_position(np.repeat(k, 4), when.ravel()).reshape(m, 4, 3)
    if peered.any():
        tag[peered] = first.positions[peer[peered], None, :]
    d = np.linalg.norm(tag - where[:, None, :], axis=2)
    tof = d / SPEED_OF_LIGHT
    effect = ExchangeEffects(z[:, 7] < r.timeout_prob, np.zeros(m), np.zeros(m), z[:, 8],
                             z[:, 7], np.zeros(m, dtype=bool))
    hits = []  # (fault, the exchanges it changed): the ledger's marks
    for i in present:
        if anchors[i].faults:
            mine = g == i
            for f in anchors[i].faults:
                on = mine & f.active(t0)
                acted = f.act(effect, on)
                hits.append((f, on if acted is None else acted))
    timeout, attenuation = effect.timeout, effect.attenuation_db
    bias = first.bias[idx] + effect.bias_m
    for i in present:
        if anchors[i].multipath is not None:
            mine = g == i  # an anchor's exchanges are in time order within its run
            bias[mine] += anchors[i].multipath.error(t0[mine], tag[mine, 0, :2])
    sigma = r.sigma0_m + r.sigma_per_m * d
    det = (r.scale - 1) * tof + (bias / SPEED_OF_LIGHT)[:, None] + 2 * sigma / SPEED_OF_LIGHT * z[:, 2:6]
    rt1 = tof[:, 0] + det[:, 0] + p_t + tof[:, 1] + det[:, 1]
    rt3 = tof[:, 2] + det[:, 2] + p_a + tof[:, 3] + det[:, 3]
    taus = np.column_stack((rt1 * (1 + e_a), p_t * (1 + e_t), rt3 * (1 + e_t), p_a * (1 + e_a)))
    taus = np.clip(np.rint(taus * PS_PER_S), 0, U32).astype(np.int64)
    value_error = effect.value_error & ~timeout
    taus[timeout | value_error] = 0
    rssi = r.rssi_1m_dbm - 10 * r.path_loss_exponent * np.log10(np.maximum(d[:, 0], 0.1)) \
        + r.shadowing_db * z[:, 6] - attenuation
    rssi = np.clip(np.rint(rssi), -128, 127).astype(np.int64)
    done = rt1 + gap + rt3 + r.result_us * 1e-6
    result = t0 + np.rint(np.where(timeout, r.timeout_ms * 1e-3, done) * 1e9).astype(np.int64)
    t_us = np.floor(network_us)
    # each network's in start order (slots never overlap: results come in this order)
    order = np.lexsort((t0, seg))
    if r.radio_range_m is not None:  # beyond the range the tag never hears the anchor
        order = order[d[order, 0] <= r.radio_range_m]
    bounds = np.searchsorted(seg[order], np.arange(len(nets) + 1)).tolist()
    marks: list[dict[int, tuple]] = [{} for _ in nets]
    if hits:
        rank = np.full(m, -1, dtype=np.int64)
        rank[order] = np.arange(len(order))
        for f, acted in hits:
            for j in np.flatnonzero(acted & (rank >= 0)).tolist():
                net = int(seg[j])
                at = int(rank[j]) - bounds[net]  # the report's index in its network's block
                marks[net][at] = marks[net].get(at, ()) + (
                    {"kind": f.KIND, "fault": f, "t_ns": int(t0[j]), "anchor": int(first.ids[idx[j]])},)
    return {
        "anchor": first.ids[idx][order],
        "tag": np.where(peered, first.ids[peer], first.tags[tag_of])[order],
        "start_ns": t0[order],
        "t_us": t_us.astype(np.int64)[order],
        "status": np.select([timeout, value_error], [STATUS_TIMEOUT, STATUS_VALUE_ERROR],
                            STATUS_COMPLETE)[order],
        "rssi": np.where(timeout, RSSI_NONE, rssi)[order],
        "tau": taus[order],
        "ready_ns": result[order] + first.latency_ns,
    }, marks, bounds
