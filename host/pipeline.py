"""Bytes -> time-stamped measurement records (host.measurements) -> estimator, as a pure
function of the input.

The input is the sequence of chunks ``(port, bytes, arrival ns since start)`` in the
order the host processed them (live) or recorded them (replay). Nothing here reads a
clock: the same chunks give the same estimates, bit for bit.

Ports (also the names of a host recording's files): those whose declaration
(protocols.ports) the host reads, each decoded as its declared format (protocols.formats),
whose frames it handles by what they carry:

=========  ==========================================================================
imu        SINS samples (type 01, or the wide type 03: the frame's type says which words,
           no setting): on the lab's ``sins`` line, and inside the coordinator's 0x90
           packets on ``xbee`` (:class:`navtwin.protocols.stream.XBeeSinsChain`); the
           stream's magnetometer frames too (``MagSample``, at their sample's time)
ranges     the anchors' gateway (``nanoloc``): one ranging report per exchange
radio      the coordinator's own frames: 0x88 DB answers give link quality, 0x88 AP
           answers the coordinator's API mode (a mismatch is an event); the host writes
           its AT queries to the port whose declaration says ``host_writes``
other      a format the host has no use for (a user's port): its frames are counted
=========  ==========================================================================

Time. Each SINS sample's host time comes from the board's counter and each range's from
the anchor network's ``t_us``, both through :class:`navtwin.host.clock.DeviceClock` (unwrapped,
aligned to arrival times online, never stepping back). A sample counter seen on both
``xbee`` and ``sins`` is one stream: the second copy of a sample is a duplicate. A clock
that begins a new epoch (its device restarted) is passed on as a ``Restart(t, "imu" |
"anchors")`` record (host.measurements) in time order: just before the first sample, or
range, of the epoch (for the IMU with the board's uptime, its counter x 10 ms: it counts
from power-up). The first SINS sample of the run carries that uptime too (``uptime_s``): a
host that started late aligns on what is left of the stationary start.

Time order, with bounded latency (docs/host.md), for each vehicle. Let T be its filter
time: the latest measurement time given to its estimator. Every measurement is given with
its own time.

* A SINS sample is processed as soon as it is decoded (its times strictly increase).
* A range with t <= T is late: it is processed at once (the estimator applies it with its
  lag, or refuses it beyond its ``max_lag_s``); the pipeline counts it and its lateness.
* A range with t > T is held until a SINS sample with time >= t is decoded (it is
  processed just before that sample), or until a chunk arrives ``hold_s`` or more after the
  range's own chunk did, on any port (the IMU stream stalled), or the input ends. Without a
  SINS input nothing is held beyond the chunk that carried it.

So SINS samples wait for nothing, ranges at most one SINS period in normal operation and
``hold_s`` of arrival time when the IMU stream stalls. The hold counts from the range's
arrival, not its time: when the host itself stalls, every port's bytes arrive late
together, and the SINS samples that come with the range still go after it.
"""
from __future__ import annotations

import heapq
import math
from collections import Counter, deque
from functools import partial
from typing import Any, Callable

from navtwin.protocols import formats, nanoloc, ports, sins, xbee
from navtwin.protocols.stream import DecodeError, Frame

from .clock import DeviceClock, Unwrapper
from .config import HostConfig
from .estimator import Estimator
from .measurements import AnchorExchange, Exchange, ImuSample, MagSample, Restart

DB_PERIOD_S = 5.0  # AT query period, in arrival time
#: asked every DB_PERIOD_S: link quality, and the coordinator's API mode (another client's
#: ATAP1 would switch it under the host)
AT_QUERIES = (b"DB", b"AP")
T_US_TICK_S = 1e-6


def imu_clock() -> DeviceClock:
    """A SINS stream's clock: the board's 16-bit sample counter, a tick a sample, strict."""
    return DeviceClock(16, sins.PERIOD_S, strict=True)


def anchor_clock() -> DeviceClock:
    """The anchor network's clock: its 32-bit ``t_us``, not strict (an exchange may be older)."""
    return DeviceClock(32, T_US_TICK_S, strict=False)


def report_counter() -> Unwrapper:
    """The gateway's report counter: equal = a duplicate, any step back = a restart."""
    return Unwrapper(16, restart=0)


def _with_vehicle(fn: Callable, vehicle: int, t, filter, kind, dim, nis, accepted) -> None:
    """An estimator's innovation, passed on with its vehicle's number."""
    fn(t, vehicle, filter, kind, dim, nis, accepted)


class Vehicle:
    """One vehicle's inputs: its SINS stream's clock, its estimator, and the records of the
    anchor clock held for it (time order is each vehicle's: its ranges wait for its own
    SINS samples)."""

    def __init__(self, number: int, settings, estimator) -> None:
        self.number = number  # 1, 2, ... in the host config's order
        self.router = None if settings.router is None else int(settings.router, 16)
        self.tag = settings.tag  # None: every tag's exchanges (a lab with one vehicle)
        self.gyro_range_dps = settings.gyro_range_dps
        self.imu_clock = imu_clock()
        self.estimator = estimator
        self.held: list[tuple] = []  # heap of (t, n, Exchange | Restart)
        self.arrived: deque[tuple[float, float]] = deque()  # (arrival, t) of each held record
        self.t = -math.inf  # filter time: the latest measurement time given to the estimator
        self.sample: tuple[int, float] | None = None  # (seq, t) of its latest SINS sample
        self.mag_seq: int | None = None  # seq of the last magnetometer frame taken
        self.estimates: Counter = Counter()

    def stats(self) -> dict:
        return {"vehicle": self.number, "router": None if self.router is None else
                f"{self.router:016X}", "tag": self.tag, "imu_clock": self.imu_clock.stats(),
                "held": len(self.held), "estimates": dict(self.estimates),
                "filter_time": None if self.t == -math.inf else self.t,
                "estimator": self.estimator.stats()}


class Pipeline:
    """Decoders, clocks, time order and the estimators of the lab's vehicles for one run of
    the host.

    The anchors' clock and the gateway's report counter are the anchor network's, shared;
    each vehicle (host config, :class:`Vehicle`) has its SINS stream, routed by the radio's
    address (``router``; with one vehicle and none configured, the first router heard), its
    exchanges, routed by ``tag`` (with one vehicle and none configured, every tag), and its
    estimator. The direct ``sins`` line is vehicle 1's.
    """

    def __init__(self, config: HostConfig, filters: tuple[str, ...] | None = None, *,
                 inputs: tuple[str, ...] | None = None, escaped: bool = True,
                 make_estimator: Callable | None = None, db_period_s: float = DB_PERIOD_S,
                 on_innovation: Callable | None = None) -> None:
        readable = ports.host_inputs()
        inputs = readable if inputs is None else inputs
        unknown = set(inputs) - set(readable)
        if unknown:
            raise ValueError(f"unknown input {sorted(unknown)[0]!r}; use {', '.join(readable)}")
        self.config = config
        self.filters = tuple(filters or config.filters)
        make_estimator = make_estimator or Estimator  # EstimatorConfig -> estimator
        self.vehicles = [Vehicle(n, v, make_estimator(config.estimator_config(self.filters, n)))
                         for n, v in enumerate(config.vehicles, 1)]
        if on_innovation is not None:  # opt-in: fn(t, vehicle, filter, kind, dim, nis, accepted)
            for v in self.vehicles:
                v.estimator.on_innovation = partial(_with_vehicle, on_innovation, v.number)
        self._by_router = {v.router: v for v in self.vehicles if v.router is not None}
        self._by_tag = {v.tag: v for v in self.vehicles if v.tag is not None}
        self._anchor_ids = frozenset(config.anchors)  # once: every report asks (a property builds the dict)
        self.inputs = tuple(p for p in readable if p in inputs)
        self.escaped = escaped
        declared = [ports.get(p) for p in self.inputs]
        self._decoders: dict[str, Any] = {p.name: formats.get(p.format).make(escaped=escaped)
                                          for p in declared}
        #: the ports the host writes its AT queries to (the coordinator's)
        self._queried = {p.name for p in declared if p.host_writes}
        self._hold = config.hold_s if any(p.carries_imu for p in declared) else 0.0
        self._handlers = {"imu": self._imu, "ranges": self._range, "radio": self._xbee}
        self._handler_of: dict[str, Callable] = {}  # frame format -> its handler
        self.range_clock = anchor_clock()
        self._report_seq = report_counter()
        self._n = 0  # tie-break of held records: the order they came in
        self._arrival = 0.0
        self._db_period = db_period_s
        self._next_db = 0.0
        self._frame_id = 0
        self._tx = bytearray()
        self._events_out: list[dict] = []
        self.link_dbm: int | None = None
        self.modem_status: int | None = None
        self.coordinator_api: int | None = None  # the AP the coordinator last answered
        self._api_mismatch = False
        self.errors: dict[str, Counter] = {p: Counter() for p in self.inputs}
        self.counts: Counter = Counter()
        self.max_late_s = 0.0

    # -- input ------------------------------------------------------------------------------
    def feed(self, port: str, data: bytes, t_ns: int) -> list:
        """Process one chunk that arrived at *t_ns* (ns since start); the estimates it gives."""
        a = t_ns * 1e-9
        self._arrival = a
        out: list = []
        self._events(port, self._decoders[port].feed(data), a, out)
        if port in self._queried and a >= self._next_db:
            for command in AT_QUERIES:
                self._query(command)
            self._next_db = a + self._db_period
        for v in self.vehicles:
            until = -math.inf
            while v.arrived and v.arrived[0][0] <= a - self._hold:
                until = max(until, v.arrived.popleft()[1])
            self._release(v, until, out)
        return out

    def finish(self) -> list:
        """End of input: what the decoders still buffer, then every held range."""
        out: list = []
        for port, dec in self._decoders.items():
            self._events(port, dec.flush(), self._arrival, out)
        for v in self.vehicles:
            self._release(v, math.inf, out)
        return out

    def take_tx(self) -> bytes:
        """Bytes the host should send to the coordinator (AT DB and AP queries); cleared."""
        tx, self._tx = bytes(self._tx), bytearray()
        return tx

    def take_events(self) -> list[dict]:
        """Status events since the last call (the coordinator's API mode); cleared."""
        events, self._events_out = self._events_out, []
        return events

    # -- decoding ---------------------------------------------------------------------------
    def _events(self, port: str, events: list, a: float, out: list) -> None:
        for ev in events:
            if isinstance(ev, DecodeError):
                kind = ev.kind if ev.format in (port, "") else f"{ev.format}_{ev.kind}"
                self.errors[port][kind] += 1
                continue
            if not ev.known:
                self.counts[f"{ev.format}_unknown_type"] += 1
                continue
            handler = self._handler_of.get(ev.format)
            if handler is None:
                handler = self._handler_of[ev.format] = self._handlers.get(
                    formats.get(ev.format).carries, self._other)
            handler(ev, a, out)

    def _other(self, ev: Frame, a: float, out: list) -> None:
        """A frame of a format the host has no use for (a user's port): counted."""
        self.counts[f"{ev.format}_frames"] += 1

    def _xbee(self, ev: Frame, a: float, out: list) -> None:
        f = ev.fields
        command = f.get("command", b"").upper()  # any client's answer: "ap" is AP too
        if ev.type == xbee.FrameType.AT_RESPONSE and command == b"DB":
            if f["status"] == xbee.AtStatus.OK and len(f["value"]) == 1:
                self.link_dbm = -f["value"][0]
                self.counts["db_answers"] += 1
        elif ev.type == xbee.FrameType.AT_RESPONSE and command == b"AP":
            if f["status"] == xbee.AtStatus.OK and len(f["value"]) == 1:
                self._api_mode(f["value"][0])
            elif f["status"] == xbee.AtStatus.OK and not f["value"]:
                self._next_db = self._arrival  # someone set AP: ask what it is now
        elif ev.type == xbee.FrameType.MODEM_STATUS:
            self.modem_status = f["status"]
            self.counts["modem_status"] += 1
        elif ev.type != xbee.FrameType.RECEIVE_PACKET:
            self.counts["xbee_other"] += 1

    def _api_mode(self, mode: int) -> None:
        """The coordinator answered AP = *mode*: an event when it starts or stops differing
        from the mode this host decodes."""
        self.coordinator_api = mode
        host = 2 if self.escaped else 1
        mismatch = mode != host
        self.counts["api_mode_mismatch"] += mismatch
        if mismatch == self._api_mismatch:
            return
        self._api_mismatch = mismatch
        event = {"event": "api_mode_mismatch" if mismatch else "api_mode_ok",
                 "coordinator_api": mode, "host_api": host}
        if mismatch:
            restart = {1: "restart the host with --api1 or ", 2: "restart the host without "
                       "--api1 or "}.get(mode, "")
            event["message"] = (f"coordinator switched to API {mode}; the host decodes API "
                                f"{host}: {restart}send ATAP{host}")
        self._events_out.append(event)

    def _query(self, command: bytes) -> None:
        # a frame ID whose request has no byte to escape: the request then reads the same
        # in API mode 1 and 2, so the coordinator answers it in either mode
        while True:
            self._frame_id = self._frame_id % 255 + 1  # 0 would ask for no answer
            frame = xbee.build(xbee.FrameType.AT_COMMAND, False, frame_id=self._frame_id,
                               command=command, parameter=b"")
            if xbee.escape(frame[1:]) == frame[1:]:
                break
        self._tx += frame
        self.counts[f"{command.decode().lower()}_queries"] += 1

    # -- measurements ---------------------------------------------------------------------------
    def _imu(self, ev: Frame, a: float, out: list) -> None:
        v = self._vehicle_of(ev.source)
        if v is None:
            self.counts["imu_other_router"] += 1
            return
        if ev.type == sins.TYPE_MAGNETOMETER:
            self._magnetometer(v, ev, out)
            return
        restarts, first = v.imu_clock.restarts, v.imu_clock.counter.last is None
        t = v.imu_clock.time(ev.fields["seq"], a)
        if t is None:
            return
        s = sins.to_sample(ev.type, ev.fields, v.gyro_range_dps)  # either width: by its type
        nd_ok = all(s.nd)
        self.counts["imu"] += 1
        self.counts["imu_no_new_data"] += not nd_ok
        self.counts["imu_alarm"] += s.ea
        self._release(v, t, out)
        v.t = max(t, v.t)
        if v.imu_clock.restarts != restarts:  # the board restarted: so did its strapdown;
            # it counts its samples from power-up, so this one says how long it has been up
            self._give(v, Restart(t, "imu", ev.fields["seq"] * sins.PERIOD_S), out)
        # the board counts its samples from power-up: the first one says how long it has
        # been up (a host that started late, under load, missed part of its alignment)
        uptime = ev.fields["seq"] * sins.PERIOD_S if first else None
        v.sample = (ev.fields["seq"], t)
        self._give(v, ImuSample(t, s.gyro_rad_s, s.accel_m_s2, nd_ok, uptime), out)

    def _magnetometer(self, v: Vehicle, ev: Frame, out: list) -> None:
        """A magnetometer frame: timed by the sample frame it follows (same seq), which the
        board wrote just before it; without that sample (lost, or a second copy of the
        stream) it has no time and is counted."""
        seq, field = ev.fields["seq"], sins.field_ut(ev.fields["field"])
        if v.sample is None or v.sample[0] != seq or v.mag_seq == seq:
            self.counts["magnetometer_untimed"] += 1
            return
        v.mag_seq = seq
        if field is None:
            self.counts["magnetometer_overflow"] += 1
            return
        self.counts["magnetometer"] += 1
        self._give(v, MagSample(v.sample[1], field), out)

    def _vehicle_of(self, source: int | None) -> Vehicle | None:
        """The vehicle of a SINS sample from radio *source* (None: the direct line)."""
        if source is None:
            return self.vehicles[0]
        v = self._by_router.get(source)
        if v is None and len(self.vehicles) == 1 and not self._by_router:
            v = self.vehicles[0]  # no router configured: the first one heard is the vehicle's
            v.router = source
            self._by_router[source] = v
        return v

    def _range(self, ev: Frame, a: float, out: list) -> None:
        f = ev.fields
        self.counts["reports"] += 1
        # the gateway counts every report, whichever tag: lost and repeated reports are
        # counted before the host picks its vehicles' (a host following some of the tags on
        # a shared network loses nothing by skipping the others)
        _, step = self._report_seq.unwrap(f["seq"], a)
        if step is not None:
            if step <= 0:
                self.counts["reports_duplicate"] += 1
                return
            self.counts["reports_lost"] += step - 1
        # an anchor's id in the tag field: two anchors ranged each other, for every vehicle
        among = f["tag"] in self._anchor_ids and f["tag"] not in self._by_tag
        v = self._by_tag.get(f["tag"], None if self._by_tag else self.vehicles[0])
        if v is None and not among:
            self.counts["reports_other_tag"] += 1
            return
        restarts = self.range_clock.restarts
        t = self.range_clock.time(f["t_us"], a)
        if self.range_clock.restarts != restarts:  # the anchors restarted: in order, before t
            for each in self.vehicles:
                self._schedule(each, Restart(t, "anchors"), out)
        if f["anchor"] not in self._anchor_ids:
            self.counts["reports_unknown_anchor"] += 1
            return
        status = f["status"]
        distance = nanoloc.distance(*f["tau"]) if nanoloc.is_complete(status) else None
        if among:
            self.counts["anchor_exchanges"] += 1
            for each in self.vehicles:
                self._schedule(each, AnchorExchange(t, f["anchor"], f["tag"], distance, f["rssi"], status), out)
            return
        if distance is not None:
            self.counts["ranges"] += 1
        else:
            self.counts["timeouts" if status & nanoloc.STATUS_TIMEOUT else "range_errors"] += 1
        self._schedule(v, Exchange(t, f["anchor"], distance, f["rssi"], status), out)

    def _schedule(self, v: Vehicle, record, out: list) -> None:
        """Hold an anchor-clock record (an exchange or the anchors' restart) for vehicle *v*
        or apply it now."""
        if record.t > v.t:
            heapq.heappush(v.held, (record.t, self._n, record))
            v.arrived.append((self._arrival, record.t))
            self._n += 1
        else:
            self._apply_range(v, record, out)

    def _release(self, v: Vehicle, until: float, out: list) -> None:
        held = v.held
        while held and held[0][0] <= until:
            self._apply_range(v, heapq.heappop(held)[2], out)

    def _apply_range(self, v: Vehicle, record, out: list) -> None:
        if record.t < v.t and type(record) is Exchange:
            self.counts["ranges_late"] += 1
            self.max_late_s = max(self.max_late_s, v.t - record.t)
        v.t = max(record.t, v.t)
        self._give(v, record, out)

    @staticmethod
    def _give(v: Vehicle, record, out: list) -> None:
        estimates = v.estimator.feed(record)
        for e in estimates:
            v.estimates[e.filter] += 1
        out += estimates

    # -- status -------------------------------------------------------------------------------
    def stats(self) -> dict:
        """Counters of everything the pipeline saw (part of the status and summary lines);
        each vehicle's under ``vehicles``, in order."""
        return {
            # frames: the port's own (the coordinator's: its API frames)
            "ports": {p: {"bytes": dec.bytes, "frames": dec.frames, "errors": dict(self.errors[p])}
                      for p, dec in self._decoders.items()},
            "counts": dict(sorted(self.counts.items())),
            "held": sum(len(v.held) for v in self.vehicles),
            "max_late_ms": self.max_late_s * 1e3,
            "anchor_clock": self.range_clock.stats(),
            "link_dbm": self.link_dbm,
            "modem_status": self.modem_status,
            "coordinator_api": self.coordinator_api,
            "vehicles": [v.stats() for v in self.vehicles],
        }
