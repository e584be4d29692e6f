"""One regular run's input chunks -> its :class:`~navtwin.host.batch.estimator.Stream`, in
numpy over whole arrays: what the host's :class:`~navtwin.host.pipeline.Pipeline` with an
estimator that keeps its records, then :func:`~navtwin.host.batch.estimator.stream`, give,
bit for bit, or :class:`~navtwin.host.batch.estimator.Unbatchable` (a short reason) for a run
that is not regular, which the caller then sends through the pipeline (lab.batch).

The input is each port's chunks as arrays, ``{port: (data, sizes, start_ns)}`` (data: the
chunks joined; sizes and device start times int64), the ports' bauds, and the pipeline's
settings (``config``, ``filters``, ``inputs``, ``escaped``; lab.run.lab_ports).

Regular, and what each step reproduces:

1. Arrival (host.arrival): chunk k of a port arrives at ``start_ns + wire_ns(size, baud)``;
   the chunks are merged by (arrival, port order, index) and the stamps made strictly
   increasing, s_i = max(t_i, s_{i-1} + 1), which is ``cummax(t_i - i) + i`` in integers.
   Regular: each port's arrivals are in its own order (what heapq.merge assumes).
2. Decoding (protocols.stream). ``xbee``, API mode 2 only: every chunk is one whole escaped
   API frame, a lone ``7E`` first, valid escapes, its length and checksum right; the 0x90
   packets of the vehicle's router (the configured one, or the only one heard) carry the
   SINS stream, other frames give no record (the pipeline only counts them). The direct
   ``sins`` line's chunks are the stream itself. The stream is SINS frames of one sample
   type back to back from its first byte (type 01, or the wide type 03; sync, len and CRC
   checked row-wise, protocols.crc.RowsCrc), a tail shorter than a frame giving no frame;
   a frame is decoded with the chunk that holds its last byte. ``nanoloc``: every chunk is
   one report of one type (01, or the wide 02), its CRC right. The payloads are read through
   numpy types made from the construct declarations (protocols.fast.rows_layout).
   Not regular: magnetometer frames (type 02 in the SINS stream), several types, API mode
   1, several vehicles in the host config, a second router without one configured, an
   exchange between anchors, an unknown anchor.
3. Units: the pipeline's float operations in its order: type 01's ``(s14 * lsb) * pi/180``
   and ``(s14 * ACCEL_LSB_G) * g`` (adis16350.words_to_sample, then Sample's properties),
   type 03's 32-bit words likewise (adis16488.to_sample); ND of every word the frame's
   flags check; ``c * (tau1 - tau2 + tau3 - tau4) * ps / 4`` for a complete exchange
   (nanoloc.distance); ``uptime_s`` = the first sample's counter x 10 ms.
4. Clocks (host.clock). The counters' unwrapping in closed form: the report counter and the
   sample counter step forward (lost reports and samples allowed: their counts only), never
   by a wrap's worth, the anchors' t_us strictly forward; a duplicate, a step back or a
   restart is not regular. The alignment: within a block of device time the rate is
   constant and the offset a running minimum, so each block is a few array operations and
   one real :meth:`~navtwin.host.clock.ClockAligner.close_block` (the hull fit) between
   blocks; a clock reset (a point ``step_s`` below the line) is not regular, nor a sample
   whose time the strict stream's +1e-6 rule would move. The anchors' non-strict rule is a
   running maximum.
5. Time order (host.pipeline's hold rule): each exchange is given late at once, or held
   until the first sample after it with time >= its own, or until the end of the first
   chunk that arrives ``hold_s`` after its own (then with every held exchange up to the
   latest time among those timed out), or the end; released in (t, arrival order). When
   no hold times out (office's runs) that is a sort of whole arrays; otherwise a Python
   loop over the exchanges only (the convoy's, whose coordinator carries three cars).

The samples then pass :func:`~navtwin.host.batch.estimator.stream`'s checks (ND set, no gap
longer than the estimator's ``imu_gap_s``). Equality with the pipeline's records:
tests/lab/test_bulk_records.py, on seeds of every shipped scenario and on runs broken on
purpose.
"""
from __future__ import annotations

import heapq
import math
from bisect import bisect_left
from collections.abc import Mapping

import numpy as np

from navtwin.protocols import adis16350, adis16488, formats, nanoloc, sins, xbee
from navtwin.protocols import ports as port_declarations
from navtwin.protocols.crc import crc16_rows
from navtwin.protocols.crcframe import HEADER, TRAILER
from navtwin.protocols.fast import rows_layout
from navtwin.protocols.stream import Frame, sins_decoder

from ..arrival import processing_order
from ..clock import MIN_STEP_S, DeviceClock, Unwrapper
from ..pipeline import anchor_clock, imu_clock, report_counter
from .estimator import EXCHANGE, IMU, Stream, Unbatchable

#: the formats of the inputs this path reads: the coordinator's, the SINS line's, the gateway's
_READ = (formats.XBEE_SINS.name, formats.SINS.name, formats.NANOLOC.name)
#: the payload types of the frames this path reads, from the declarations
_SINS = {t: rows_layout(sins.LAYOUTS[t]) for t in sins.SAMPLE_TYPES}
_REPORTS = {t: rows_layout(nanoloc.LAYOUTS[t]) for t in nanoloc.LAYOUTS}
_RECEIVE = rows_layout(xbee.ReceivePacket)  # 0x90's fixed fields, before its data
_ESCAPED = np.zeros(256, bool)
_ESCAPED[[b ^ 0x20 for b in xbee.ESCAPED_BYTES]] = True  # what may follow a 7D
_MAX_FRAME_DATA = 1024  # the decoders' bound (protocols.stream.XBeeDecoder)
_RAD = math.pi / 180.0  # adis16350.Sample's


def bulk_stream(ports: Mapping[str, tuple[bytes, np.ndarray, np.ndarray]],
                bauds: Mapping[str, int], settings: Mapping, gap_s: float) -> Stream:
    """The :class:`Stream` of vehicle 1's records in the run whose input chunks are *ports*
    (``{port: (data, sizes, start_ns)}``, *bauds*) under the pipeline's *settings*
    (lab.run.lab_ports' ``kw``), for an estimator whose ``imu_gap_s`` is *gap_s*; or
    :class:`Unbatchable` (module doc)."""
    config, inputs = settings["config"], tuple(settings["inputs"])
    if len(config.vehicles) != 1:
        raise Unbatchable("several vehicles")
    declared = {p: port_declarations.get(p) for p in inputs}
    imu_ports = [p for p, d in declared.items() if d.carries_imu]
    report_ports = [p for p, d in declared.items() if d.format == formats.NANOLOC.name]
    if any(d.format not in _READ for d in declared.values()) or len(imu_ports) > 1 \
            or len(report_ports) > 1:
        raise Unbatchable(f"inputs {', '.join(inputs)}")
    try:
        at, stamp = processing_order({p: ports[p] for p in inputs}, bauds)
    except ValueError as e:
        raise Unbatchable(str(e)) from None
    arrival = stamp * 1e-9  # the pipeline's ``t_ns * 1e-9``, in processing order
    vehicle = config.vehicles[0]
    hold = config.hold_s if imu_ports else 0.0

    empty = np.zeros(0, np.int64)
    payload, chunk, payload_ends, pos = np.zeros(0, np.uint8), empty, empty, empty
    for port in imu_ports:
        if declared[port].format == formats.XBEE_SINS.name:
            if not settings["escaped"]:
                raise Unbatchable("XBee API mode 1")
            router = None if vehicle.router is None else int(vehicle.router, 16)  # as Vehicle's
            payload, chunk, payload_ends = _receive_packets(ports[port], router)
        else:  # the direct line: its chunks are the stream
            data, sizes, _ = ports[port]
            payload, chunk, payload_ends = (np.frombuffer(data, np.uint8), np.arange(len(sizes)),
                                            np.cumsum(sizes))
        pos = at[port]
    ftype, fields, last_byte = _sins_frames(payload)
    # a frame is decoded with the chunk that brings its last byte
    pos_imu = pos[chunk[np.searchsorted(payload_ends, last_byte, side="right")]]
    t_imu = _imu_times(fields["seq"].astype(np.int64), arrival[pos_imu])
    gyro, accel, nd_ok = _units(ftype, fields, vehicle.gyro_range_dps)
    pos_r, t_r, anchor, distance, status = empty, np.zeros(0), empty, np.zeros(0), empty
    for port in report_ports:
        pos_r, t_r, anchor, distance, status = _exchanges(
            ports[port], at[port], arrival, vehicle.tag, frozenset(config.anchors))

    if not nd_ok.all():
        raise Unbatchable("IMU sample stale")
    if len(t_imu) > 1 and (np.diff(t_imu) > gap_s).any():  # stream(): Inertial.gap
        raise Unbatchable("IMU gap")
    slot, emitted = _time_order(t_imu, pos_imu, t_r, pos_r, arrival, hold)
    n_imu, n = len(t_imu), len(t_imu) + len(t_r)
    # the records in the pipeline's order: the exchanges of slot k (in the order given) just
    # before sample k
    rank = np.argsort(np.concatenate((2 * slot, 2 * np.arange(n_imu) + 1)), kind="stable")
    is_imu = rank >= len(slot)
    kind = np.where(is_imu, IMU, EXCHANGE).astype(np.int8)
    take_r = emitted[rank[~is_imu]]
    take_i = rank[is_imu] - len(slot)
    t = np.empty(n)
    t[is_imu], t[~is_imu] = t_imu[take_i], t_r[take_r]
    g, a = np.zeros((n, 3)), np.zeros((n, 3))
    g[is_imu], a[is_imu] = gyro[take_i], accel[take_i]
    uptime = np.full(n, np.nan)
    if n_imu:  # the first sample the host sees: how long the board has been up
        uptime[np.flatnonzero(is_imu)[0]] = int(fields["seq"][0]) * sins.PERIOD_S
    anchors, dist, stat = np.zeros(n, np.int64), np.full(n, np.nan), np.zeros(n, np.int64)
    anchors[~is_imu], dist[~is_imu], stat[~is_imu] = anchor[take_r], distance[take_r], status[take_r]
    return Stream(kind, t, g, a, uptime, anchors, dist, stat)


# -- decoding ----------------------------------------------------------------------------------

def _receive_packets(port, router: int | None):
    """The SINS stream of the vehicle's router in an ``xbee`` port's chunks, its 0x90
    packets' chunks, and the stream's offset where each packet's data ends."""
    data, sizes, _ = port
    raw = np.frombuffer(data, np.uint8)
    n = len(sizes)
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    if n and ((sizes < 1).any() or (raw[starts] != xbee.START).any()
              or np.count_nonzero(raw == xbee.START) != n):
        raise Unbatchable("an xbee chunk that is not one API frame")
    esc = np.flatnonzero(raw == xbee.ESCAPE)
    if len(esc) and (esc[-1] + 1 >= len(raw) or not _ESCAPED[raw[esc + 1]].all()):
        raise Unbatchable("a bad escape")
    u = raw.copy()
    u[esc + 1] ^= 0x20
    keep = np.ones(len(u), bool)
    keep[esc] = False
    u = u[keep]
    us = starts - np.searchsorted(esc, starts)  # each frame's 7E, unescaped
    usize = np.diff(np.append(us, len(u)))
    u16 = u.astype(np.int64)
    length = np.zeros(n, np.int64)
    ok = usize >= 5
    length[ok] = u16[us[ok] + 1] << 8 | u16[us[ok] + 2]
    if not (ok & (length > 0) & (length <= _MAX_FRAME_DATA) & (usize == length + 4)).all():
        raise Unbatchable("an XBee frame's length")
    total = np.concatenate(([0], np.cumsum(u16)))
    if ((total[us + usize] - total[us + 3]) & 0xFF != 0xFF).any():
        raise Unbatchable("an XBee checksum")
    rx = np.flatnonzero(u[us + 3] == xbee.FrameType.RECEIVE_PACKET)
    fixed = _RECEIVE.itemsize
    if (length[rx] < 1 + fixed).any():
        raise Unbatchable("a malformed 0x90 packet")
    head = u[(us[rx] + 4)[:, None] + np.arange(fixed)].view(_RECEIVE)[:, 0]
    sources = head["src64"].astype(np.uint64)
    if router is None:
        heard = np.unique(sources)
        if len(heard) > 1:
            raise Unbatchable("several routers")
    else:
        rx = rx[sources == np.uint64(router)]
    first = us[rx] + 4 + fixed
    count = usize[rx] - 5 - fixed
    ends = np.cumsum(count)
    offsets = np.arange(ends[-1] if len(ends) else 0) - np.repeat(ends - count, count)
    return u[np.repeat(first, count) + offsets], rx, ends


def _sins_frames(stream: np.ndarray):
    """(type, payload fields, offset of each frame's last byte) of a SINS stream of frames
    of one sample type back to back."""
    if not len(stream):
        return sins.TYPE_SAMPLE, np.zeros(0, _SINS[sins.TYPE_SAMPLE]), np.zeros(0, np.int64)
    ftype = int(stream[2]) if len(stream) > 2 else -1
    if ftype not in _SINS:
        raise Unbatchable("a SINS stream not of sample frames from its first byte")
    layout = _SINS[ftype]
    size = HEADER + layout.itemsize + TRAILER
    n = len(stream) // size
    rows = stream[:n * size].reshape(n, size)
    if ((rows[:, 0] != sins.SYNC[0]) | (rows[:, 1] != sins.SYNC[1]) | (rows[:, 2] != ftype)
            | (rows[:, 3] != layout.itemsize)).any():
        raise Unbatchable("SINS frames not back to back, or of several types")
    if crc16_rows(rows[:, 2:]).any():  # the CRC of the covered bytes and the CRC is 0
        raise Unbatchable("a SINS CRC")
    tail = stream[n * size:]
    if len(tail) and any(type(ev) is Frame for ev in sins_decoder().decode(tail.tobytes())):
        raise Unbatchable("a frame in the SINS stream's tail")
    fields = np.ascontiguousarray(rows[:, HEADER:-TRAILER]).view(layout)[:, 0]
    return ftype, fields, np.arange(1, n + 1) * size - 1


def _units(ftype: int, fields, gyro_range: int):
    """gyro (rad/s), accel (m/s^2) and ND of each sample, as the pipeline computes them."""
    if ftype == sins.TYPE_WIDE_SAMPLE:
        g = fields["gyro"].astype(np.int64) * adis16488.GYRO_LSB_DPS * _RAD
        a = fields["accel"].astype(np.int64) * adis16488.ACCEL_LSB_G * adis16350.STANDARD_GRAVITY
        flagged = np.column_stack((fields["supply"], fields["temp"], fields["aux"]))
    else:
        w = fields["words"].astype(np.int64)
        g = adis16350.signed(w[:, 1:4], 14) * adis16350.GYRO_LSB_DPS[gyro_range] * _RAD
        a = adis16350.signed(w[:, 4:7], 14) * adis16350.ACCEL_LSB_G * adis16350.STANDARD_GRAVITY
        flagged = w
    return g, a, (flagged >= adis16350.ND).all(axis=1)


def _exchanges(port, position: np.ndarray, arrival: np.ndarray, tag: int | None,
               anchor_ids: frozenset):
    """(position, t, anchor, distance, status) of the vehicle's exchanges in the
    ``nanoloc`` port's chunks, each chunk one report."""
    data, sizes, _ = port
    if not len(sizes):
        return position, np.zeros(0), position, np.zeros(0), position
    raw = np.frombuffer(data, np.uint8)
    ftype = int(raw[2]) if len(raw) > 2 else -1
    layout = _REPORTS.get(ftype)
    size = None if layout is None else HEADER + layout.itemsize + TRAILER
    if layout is None or (sizes != size).any():
        raise Unbatchable("a nanoloc chunk that is not one report")
    rows = raw.reshape(-1, size)
    if ((rows[:, 0] != nanoloc.SYNC[0]) | (rows[:, 1] != nanoloc.SYNC[1]) | (rows[:, 2] != ftype)
            | (rows[:, 3] != layout.itemsize)).any():
        raise Unbatchable("reports of several types")
    if crc16_rows(rows[:, 2:]).any():
        raise Unbatchable("a report's CRC")
    f = np.ascontiguousarray(rows[:, HEADER:-TRAILER]).view(layout)[:, 0]
    a = arrival[position]
    _forward(f["seq"].astype(np.int64), np.diff(a), report_counter())
    tags = f["tag"].astype(np.int64)
    # an anchor's id in the tag field, not the vehicle's: two anchors ranged each other
    if (np.isin(tags, list(anchor_ids)) & (tags != (-1 if tag is None else tag))).any():
        raise Unbatchable("an exchange between anchors")
    mine = np.ones(len(tags), bool) if tag is None else tags == tag
    f, a, position = f[mine], a[mine], position[mine]
    anchor = f["anchor"].astype(np.int64)
    if not np.isin(anchor, list(anchor_ids)).all():
        raise Unbatchable("an unknown anchor")
    clock = anchor_clock()
    t_us = f["t_us"].astype(np.int64)
    steps = _forward(t_us, np.diff(a), clock.counter)
    device = np.concatenate(([0], np.cumsum(steps))) * clock.tick_s
    t = np.maximum.accumulate(_aligned(clock, device, a))  # not strict: never back
    tau = f["tau"].astype(np.int64)
    status = f["status"].astype(np.int64)
    d = (nanoloc.SPEED_OF_LIGHT * (tau[:, 0] - tau[:, 1] + tau[:, 2] - tau[:, 3])
         * nanoloc.PS / 4.0)
    complete = status & 0xCF == nanoloc.STATUS_COMPLETE  # nanoloc.is_complete
    return position, t, anchor, np.where(complete, d, np.nan), status


# -- clocks ------------------------------------------------------------------------------------

def _forward(raw: np.ndarray, elapsed: np.ndarray, counter: Unwrapper) -> np.ndarray:
    """The steps of *counter* (host.clock.Unwrapper, fresh) through the values *raw*, each
    *elapsed* arrival time after the last, when every value is newer than the last by less
    than half a wrap around what that time predicts, and none is a restart; else
    Unbatchable (a duplicate, a step back, a restart: the pipeline's rarer branches)."""
    m = counter.modulus
    d = (raw[1:] - raw[:-1]) % m
    expected = elapsed / counter.tick_s if counter.tick_s else np.ones(len(d))
    if (d < 1).any() or (np.floor((expected - d) / m + 0.5) != 0).any():
        raise Unbatchable("a counter's duplicate or step back")
    # a step far from the prediction restarts, unless it is forward but behind it (late)
    if counter.restart is not None and counter.tick_s and \
            not ((np.abs(d - expected) <= counter.restart) | (d < expected)).all():
        raise Unbatchable("a device restart")
    return d


def _imu_times(seq: np.ndarray, arrival: np.ndarray) -> np.ndarray:
    """The samples' host times (host.pipeline's imu_clock), or Unbatchable."""
    if not len(seq):
        return np.zeros(0)
    clock = imu_clock()
    steps = _forward(seq, np.diff(arrival), clock.counter)
    device = np.concatenate(([0], np.cumsum(steps))) * clock.tick_s
    t = _aligned(clock, device, arrival)
    if (t[1:] < t[:-1] + MIN_STEP_S).any():
        raise Unbatchable("the IMU clock's +1e-6 s step")
    return t


def _aligned(clock: DeviceClock, device: np.ndarray, arrival: np.ndarray) -> np.ndarray:
    """``aligner.to_host`` after ``aligner.add`` of each point (host.clock.ClockAligner), a
    block of device time at a time; Unbatchable where it would reset."""
    al = clock.aligner
    lag = arrival - device
    block = np.floor(device / al.block_s)
    cuts = np.flatnonzero(block[1:] != block[:-1]) + 1
    bounds = np.concatenate(([0], cuts, [len(device)])).tolist()
    out = np.empty(len(device))
    offset = rate = None
    for s, e in zip(bounds[:-1], bounds[1:]):
        dev, lg = device[s:e], lag[s:e]
        if offset is not None:
            # the reset test of the block's first point is against the line before the fit
            if lg[0] - offset - rate * dev[0] < -al.step_s:
                raise Unbatchable("a clock reset")
            al.close_block(opened)
        rate = al.rate
        low = lg - rate * dev
        run = np.minimum.accumulate(low if offset is None else np.append(al.offset, low))
        run = run[-len(low):]
        if len(low) > 1 and (lg[1:] - run[:-1] - rate * dev[1:] < -al.step_s).any():
            raise Unbatchable("a clock reset")
        k = int(np.argmin(low))
        opened = (float(dev[k]), float(lg[k]))
        offset = float(run[-1])
        out[s:e] = dev + run + rate * dev
    return out


# -- time order --------------------------------------------------------------------------------

def _time_order(t_imu, pos_imu, t_r, pos_r, arrival, hold: float):
    """Where the pipeline gives each exchange (host.pipeline's hold rule): (the sample each
    exchange given goes just before, in the order given; len(t_imu): after the last) and
    the exchanges' indices in that order.

    When no hold times out (the IMU stream never stalls: office's runs), each exchange is
    given on its own, late at once or just before the first sample after it whose time is
    not older; several before one sample in (t, arrival order), after the late ones (given
    earlier). Every exchange given is then older than the samples before the next one, so
    none moves the filter time that the others are judged late against. Otherwise
    :func:`_held_in_turn` replays the holds one release at a time."""
    first_after = np.searchsorted(pos_imu, pos_r, side="right")  # the samples after each
    t_before = np.append(-np.inf, t_imu)[first_after]  # the filter time the samples made
    # the chunk at whose end its hold times out: the first to arrive hold_s after its own
    timeout = np.maximum(np.searchsorted(arrival - hold, arrival[pos_r], side="left"), pos_r)
    late = t_r <= t_before
    by = np.maximum(first_after, np.searchsorted(t_imu, t_r, side="left"))
    at = np.append(pos_imu, len(arrival))[by]  # that sample's chunk (none: past the end)
    if (~late & (timeout < len(arrival)) & (at > timeout)).any():
        return _held_in_turn(t_imu, pos_imu, t_r, pos_r, first_after, t_before, timeout,
                             len(arrival))
    slot = np.where(late, first_after, by)
    emitted = np.lexsort((np.arange(len(t_r)), np.where(late, 0.0, t_r), ~late, slot))
    return slot[emitted], emitted


def _held_in_turn(t_imu, pos_imu, t_r, pos_r, first_after, t_before, timeout, end: int):
    """:func:`_time_order`'s result by replaying the pipeline's holds: a loop over the
    exchanges, each release (by a sample, a timeout, the end) found in the arrays."""
    n_imu, n_r = len(t_imu), len(t_r)
    chunk_slot = np.searchsorted(pos_imu, np.arange(end), side="right")
    T, P = t_imu.tolist(), pos_imu.tolist()
    tr, pr, k0, tb, jt = (x.tolist() for x in (t_r, pos_r, first_after, t_before, timeout))
    cs = chunk_slot.tolist()
    held: list = []  # heap of (t, index): index = arrival order
    waiting: list = []  # held indices in arrival order (their timeouts in order)
    w = 0
    released = [False] * n_r
    slots, emitted = [], []
    vmax = -math.inf  # the latest exchange time given
    k_next = 0  # the first sample not yet processed

    def release(until, slot):
        nonlocal vmax
        while held and held[0][0] <= until:
            t, i = heapq.heappop(held)
            released[i] = True
            slots.append(slot)
            emitted.append(i)
            vmax = max(vmax, t)

    for i in range(n_r + 1):
        here = pr[i] if i < n_r else math.inf
        while held:
            while released[waiting[w]]:
                w += 1
            k = max(k_next, bisect_left(T, held[0][0]))
            p_sample = P[k] if k < n_imu else math.inf
            j = jt[waiting[w]]
            if p_sample <= j and p_sample < here:  # a sample releases (before it is given)
                release(T[k], k)
                k_next = k
            elif j < end and j < here and j < p_sample:  # a hold times out at the chunk's end
                until, x = -math.inf, w
                while x < len(waiting) and jt[waiting[x]] <= j:
                    if not released[waiting[x]]:
                        until = max(until, tr[waiting[x]])
                    x += 1
                release(until, cs[j])
                k_next = max(k_next, cs[j])
            elif i == n_r and p_sample == math.inf and j >= end:
                release(math.inf, n_imu)  # the end of the input
            else:
                break
        if i == n_r:
            break
        k_next = k0[i]
        if tr[i] <= max(vmax, tb[i]):  # late: given at once
            slots.append(k0[i])
            emitted.append(i)
            vmax = max(vmax, tr[i])
        else:
            heapq.heappush(held, (tr[i], i))
            waiting.append(i)
    return np.array(slots, np.int64), np.array(emitted, np.int64)
