"""The emulated lab in virtual time: every device's output as timed events.

``World(sc, seed)`` builds the vehicles of scenario *sc* (:class:`Vehicle`: trajectory,
ADIS16350 and DSP board, XBee router and uplink), each coordinator's downlink and the nanoLOC
networks (one for every tag, or one per vehicle: the scenario's ``network`` keys).
``advance(until_ns)`` returns, sorted by (t_ns, port order sins < nanoloc < xbee, vehicle),
every event with t_ns < until_ns not returned before, each on its port instance (vehicle n's
``sins<n>``; protocols.ports):

- ``Event(t, "sins", bytes)``: one SINS frame; t = when the board starts writing it;
- ``Event(t, "nanoloc", bytes)``: one gateway report; t = when the gateway starts writing it;
- ``Event(t, "xbee", RfPacket)``: an RF packet the coordinator's radio received at t (after
  the router's packetisation, latency and retries; lost packets never appear); with one
  coordinator for all, every router's packets are on ``xbee``.

Routers that joined one coordinator share its channel (emulator.channel): one packet on the
air at a time, a packet waiting while another is sent, dropped when its router's queue is
full. :meth:`World.ahead` makes the blocks in a process of its own while a paced run's loop
writes (emulator.maker: a block of fifty vehicles takes a few hundred ms of CPU, which must
not hold up the writes due meanwhile, nor hold their interpreter's lock); the events are the
same wherever the blocks were made.

Beside the events, ``air(until_ns)`` returns the frames the routers' packets put on the air
(emulator.radio.AirFrame: every attempt, received or lost, and the coordinator's MAC ACK of
each received one), in time order, once ``advance`` has reached *until_ns*.

The devices run in fixed blocks of true time (BLOCK_NS); an event is generated with the
block of its cause (frame tick, packet closing, exchange start) and is never earlier than
it, so the events do not depend on how the caller slices time. Every random draw comes
from a named stream of the seed (emulator.rng). Events at or after the scenario's duration
are dropped.
"""
from __future__ import annotations

import bisect
import contextlib
from dataclasses import dataclass
from functools import lru_cache
from itertools import repeat
from operator import attrgetter

import numpy as np

from navtwin.protocols import ports
from navtwin.protocols.zigbee import COORDINATOR16

from .board import Board
from .channel import Channel, Offered
from .events import Event, RfPacket, rows
from .faults import acting_on
from .imu import Adis16350, generate_together
from .magnetometer import Magnetometer
from .nanoloc import NanolocNetwork
from .radio import OPT_ACKNOWLEDGED, AirFrame, Link, Router, Sender
from .rng import stream, vehicles_name
from .scenario import BLOCK_S, Scenario
from .trajectory import Trajectory
from .truth import truth_arrays

#: events at the same t_ns come in this port order (then vehicle order), so the event list
#: never depends on how the devices were generated
EVENT_ORDER = (ports.SINS.name, ports.NANOLOC.name, ports.XBEE.name)
_T_NS = attrgetter("t_ns")


def _port_events(t_ns: np.ndarray, port: str, data: list, marks: dict) -> list[Event]:
    """The events of one port's block: data[i] at t_ns[i], with the ledger marks by index."""
    return rows(Event, t_ns.tolist(), repeat(port), data,
                [marks.get(i, ()) for i in range(len(data))] if marks else repeat(()))


def trajectory_of(spec) -> Trajectory:
    """A vehicle's (a scenario's fleet entry) trajectory: its path, its tag's height. It
    draws nothing and holds no state after it is built, so every seed of a vehicle shares
    one (a sweep's task builds it once, not once a seed)."""
    return _trajectory(spec.trajectory, spec.tag.z)


@lru_cache(maxsize=64)
def _trajectory(spec, height: float) -> Trajectory:
    return Trajectory(spec, height)


@dataclass(slots=True)
class RouterEffects:
    """What router faults change in a block's packets: ``absent`` (bool per packet)."""

    absent: np.ndarray


class Vehicle:
    """One vehicle's devices: its trajectory, the ADIS16350 (and a magnetometer, when the
    scenario enables one) on its DSP board, and the XBee router that packetises the board's
    stream onto its RF uplink.

    Vehicle 1 draws from the streams "imu" (and "imu.gyro.drift", "imu.accel.drift" for a
    grade with a flicker bias or rate random walk), "magnetometer" and "xbee.link.router";
    vehicle n > 1 from the
    same names under "vehicle<n>.", so adding a vehicle never changes another's draws.
    """

    def __init__(self, sc: Scenario, spec, router: dict, number: int, seed: int,
                 air: bool = True) -> None:
        self.number = number
        self.air = air  # make its frames on the air (nobody may be there to take them)
        self.sins_events = True  # make the events of its SINS port (World.only)
        self.spec = spec
        self.sins_port = ports.instance(ports.SINS.name, number)
        #: the port of the coordinator its router joined (its own, or vehicle 1's)
        self.xbee_port = ports.instance(ports.XBEE.name, number if sc.units("coordinator") > 1 else 1)
        self.src64 = (router["SH"] << 32) | router["SL"]
        self.src16 = router["MY"]
        self.trajectory = trajectory_of(spec)
        self.imu = Adis16350(spec.imu, sc.site, sc.area, self.trajectory, sc.clocks.imu_ppm,
                             lambda name: self._stream(seed, name))
        mag = spec.magnetometer
        on = mag is not None and mag.enabled
        self.board = Board(spec.board, sc.clocks.board_ppm, self.imu,
                           acting_on(sc.faults, "board", vehicle=number),
                           Magnetometer(mag, sc.site, sc.area, self.trajectory,
                                        self._stream(seed, "magnetometer")) if on else None,
                           round(1000.0 / spec.board.period_ms / mag.rate_hz) if on else 0)
        self.router = Router(router["NP"], router["RO"], self.board.char_ns)
        self.uplink = Link(sc.link, acting_on(sc.faults, "link"),
                           self._stream(seed, "xbee.link.router"))
        self.sender = Sender(router["OI"])  # its frames on the air
        self.faults = tuple(acting_on(sc.faults, "router", vehicle=number))  # its router's
        self._rejoin_rng = self._stream(seed, "xbee.router.rejoin")  # new MYs after rejoins
        self._absent: dict | None = None  # the router's packets lost while out of the network

    def _stream(self, seed: int, name: str):
        return stream(seed, vehicles_name(self.number, name))

    def block(self, lo: int, hi: int, more: bool, written: tuple | None = None):
        """The board's SINS frames written in [lo, hi) and the RF packets they become (*more*:
        the run goes on after *hi*, so an open packet waits for the next bytes), each as it
        is offered to the channel (emulator.channel): its event at the coordinator (None when
        the link lost it) and its frames on the air (a packet the router sends while out of
        the network is not offered): ``(sins events, offered packets)``. *written*: the
        board's frames of the block, made already (Board.frames_together)."""
        self.imu.generate(lo, hi)
        t_sins, frames, marks = written or self.board.frames(lo, hi)
        events = _port_events(t_sins, self.sins_port, frames, marks) if self.sins_events else []
        next_byte = self.board.next_start(hi) + round(self.board.char_ns) if more else None
        times = self.board.byte_times(t_sins, [len(f) for f in frames])
        packets = self.router.packetise(b"".join(frames), times, next_byte)
        arrival, delivered, marks, attempts = self.uplink.transmit(
            packets.ready_ns, [len(p) for p in packets.payloads])
        kept, src16 = self._in_network(packets.ready_ns, marks)
        payloads = packets.payloads if len(kept) == len(packets.payloads) else \
            [packets.payloads[i] for i in kept.tolist()]
        air = self.sender.block(attempts, kept, src16.tolist(), COORDINATOR16, payloads) if self.air \
            else [[]] * len(kept)
        received = _port_events(arrival[kept], self.xbee_port, rows(
            RfPacket, repeat(self.src64), src16.tolist(), repeat(OPT_ACKNOWLEDGED), payloads),
            {j: marks[i] for j, i in enumerate(kept.tolist()) if i in marks} if marks else marks)
        received = [e if ok else None for e, ok in zip(received, delivered[kept].tolist())]
        offered = rows(Offered, repeat(self.number), attempts.start_ns[kept].tolist(),
                       attempts.service[kept].tolist(), received, air)
        return events, offered

    def _in_network(self, ready_ns, marks: dict):
        """(the block's packets the router sends while in the network, the MY each goes
        from): a packet sent while a router fault has it out is lost at the router, and the
        first one back goes from a new MY, marked in *marks* with the episode."""
        absent, cause = self._out_of_network(ready_ns)
        if absent is None:
            return np.arange(len(ready_ns)), np.full(len(ready_ns), self.src16)
        kept, src16 = [], []
        for i in range(len(ready_ns)):
            if absent[i]:
                self._absent = self._absent or {"kind": cause.KIND, "fault": cause,
                                                "t_ns": int(ready_ns[i]), "lost": 0}
                self._absent["lost"] += 1
                continue
            if self._absent is not None:  # back in the network, under a new address
                self.src16 = int(self._rejoin_rng.integers(1, 0xFFF8))
                marks[i], self._absent = marks.get(i, ()) + ({**self._absent, "my": self.src16},), None
            kept.append(i)
            src16.append(self.src16)
        return np.array(kept, dtype=np.int64), np.array(src16, dtype=np.int64)

    def _out_of_network(self, ready_ns):
        """(which packets the router sends while a router fault has it out of the network,
        that fault); (None, None) when it has no fault and is in. The episode's ledger mark
        waits in ``_absent`` until the router is back."""
        if not self.faults and self._absent is None:
            return None, None
        effect, cause = RouterEffects(np.zeros(len(ready_ns), dtype=bool)), None
        for f in self.faults:
            on = f.active(ready_ns)
            f.act(effect, on)
            cause = cause or (f if on.any() else None)
        return effect.absent, cause

    def device_truth(self) -> dict:
        """What this vehicle's devices drew at power-on and its router's join."""
        return {"imu": self.imu.errors(), "router_my": self.src16}


class World:
    BLOCK_NS = round(BLOCK_S * 1e9)  # the IMU's sample period is checked against it

    def __init__(self, sc: Scenario, seed: int | None = None, vehicles=None,
                 air: bool = True) -> None:
        """*vehicles*: the numbers of the vehicles to build (default all); a subset needs a
        network per vehicle (emulator.workers refuses the rest), and each vehicle's events equal the
        whole world's, as every vehicle draws from streams of its own. *air*: False makes no
        frames on the air (:meth:`air` returns none; the events are the same), for a run
        with nothing to take them (a sixth of the world's work)."""
        self.scenario = sc
        self.seed = sc.seed if seed is None else seed
        self.duration_ns = sc.duration_ns
        self.radios = sc.radios_for(self.seed)
        every = range(1, len(sc.fleet) + 1)
        hosted = set(every if vehicles is None else vehicles)
        self.vehicles = [Vehicle(sc, spec, router, n, self.seed, air) for n, (spec, router)
                         in enumerate(zip(sc.fleet, sc.routers_for(self.seed)), 1) if n in hosted]
        self._numbered = {v.number: v for v in self.vehicles}
        #: per coordinator's port, the host -> router direction (0x10, 0x17); each its own
        #: stream, so host activity never changes the device byte streams
        self.downlinks = {ports.instance(ports.XBEE.name, n): Link(sc.link, acting_on(sc.faults, "link"), stream(
            self.seed, vehicles_name(n, "xbee.link.coordinator")))
            for n in range(1, sc.units("coordinator") + 1) if n in hosted}
        #: per gateway's port, its network: one ranging every tag in turn, or one per vehicle
        gateways = sc.units("gateway")
        groups = {1: self.vehicles} if gateways == 1 else {v.number: [v] for v in self.vehicles}
        self.networks = {ports.instance(ports.NANOLOC.name, n): NanolocNetwork(
            sc, [v.spec.tag for v in group], [v.trajectory for v in group], self.seed,
            vehicles_name(n, "")) for n, group in groups.items()}
        self.nanoloc = self.networks.get(ports.NANOLOC.name)  # vehicle 1's
        #: per coordinator's port that several routers joined, their shared channel
        self.channels = {port: Channel() for port in self.downlinks
                         if sum(v.xbee_port == port for v in self.vehicles) > 1}
        names = [ports.instance(p, n) for p in EVENT_ORDER for n in every]
        self._rank = {name: i for i, name in enumerate(names)}
        self._generated_ns = 0  # blocks before this are generated
        #: generated, not returned, in order, and their order keys (:meth:`_wait`)
        self._events: list[Event] = []
        self._keys = np.empty(0, dtype=np.int64)
        self._returned_ns = 0
        self._air: list[AirFrame] = []  # generated, in order; those before _air_at returned
        self._air_at = 0
        self._by_port: dict[str, list[Event]] | None = None  # :meth:`by_port`
        #: while :meth:`ahead` runs, and after: the process that makes the blocks
        #: (emulator.maker), whose blocks advance, air, made and held give
        self._maker = None

    def only(self, taken) -> None:
        """From the next block on, make no events of the SINS ports not in *taken* (port
        instances): their frames still go to the routers, so every other event is the same
        (a caller that reads only the radio, lab.run's in-memory runs)."""
        for v in self.vehicles:
            v.sins_events = v.sins_port in taken

    def by_port(self, taken) -> None:
        """From the next block on, keep the events of the ports *taken* (port instances) by
        port, for :meth:`kept`, and no others (:meth:`only`): ``advance`` returns none. For
        a caller that takes each port's events of the whole run at once (the quick path
        of an in-memory run, emulator.runner.chunks_together), which needs no merge of
        the ports into one timeline."""
        self.only(taken)
        self._by_port = {port: [] for port in taken}

    def kept(self, port: str) -> list[Event]:
        """The events of *port* made so far under :meth:`by_port`, in the order made: a
        block after another, and within a block a port's own order, not sorted by time.
        They are handed over (the world keeps none of them after), so they die with the
        caller's use of them, not with the world."""
        return self._by_port.pop(port)

    # -- generation -------------------------------------------------------------------------
    def _make(self, reports: list | None = None, written: list | None = None) -> None:
        """Make the next block: each vehicle, each nanoLOC network (*reports*: their reports
        of the block, *written*: the vehicles' SINS frames, made already by
        :meth:`make_together`), and last the block sorted into the events that wait."""
        lo = self._generated_ns
        hi = min(lo + self.BLOCK_NS, self.duration_ns)
        if reports is None:
            reports = NanolocNetwork.reports_together(list(self.networks.values()), lo, hi)
        made, air = [], []  # made: each port's events of the block, in generation order
        offered: dict[str, list[Offered]] = {}
        for vehicle, frames in zip(self.vehicles, written or [None] * len(self.vehicles)):
            s, packets = vehicle.block(lo, hi, hi < self.duration_ns, frames)
            made.append((vehicle.sins_port, s))
            offered.setdefault(vehicle.xbee_port, []).append(packets)
        for port, shares in offered.items():
            channel = self.channels.get(port)
            if channel is not None:  # routers that wait for each other
                r, a = channel.share([p for share in shares for p in share])
            else:  # a router alone on its channel: its link's own schedule
                r = [p.event for share in shares for p in share if p.event is not None]
                a = [f for share in shares for p in share for f in p.air]
            made.append((port, r))
            air += a
        for port, (t_nl, frames, marks) in zip(self.networks, reports):
            made.append((port, _port_events(t_nl, port, frames, marks)))
        self._generated_ns = hi
        if self._by_port is not None:
            for port, events in made:
                if port in self._by_port:
                    self._by_port[port] += events
            return
        self._wait([e for _, events in made for e in events], np.concatenate(
            [self._keys] + [np.fromiter(map(_T_NS, events), np.int64, len(events)) * len(self._rank)
                            + self._rank[port] for port, events in made]))
        if air:  # the returned dropped here, once a block: air() copies none
            self._air = self._air[self._air_at:] + [f for f in air if f.t_ns < self.duration_ns]
            self._air.sort(key=_T_NS)  # stable: an ACK stays after its frame
            self._air_at = 0

    def _wait(self, block: list[Event], keys: np.ndarray) -> None:
        """Join the events of a *block* to those that wait, in the order :meth:`advance`
        returns them (*keys*: the order keys of those that wait, then of the block's; a key is
        (t_ns, port rank) as one integer). A block's events are never earlier than the block (module doc), so those
        that wait can take it before they are asked for: advance() returns none before their
        time. A stable sort keeps generation order among equal keys (one port's events, made
        in its order); events at or after the run's end are dropped."""
        events = self._events + block
        order = np.argsort(keys, kind="stable")
        order = order[keys[order] < self.duration_ns * len(self._rank)]
        self._keys, self._events = keys[order], [events[i] for i in order.tolist()]

    @staticmethod
    def make_together(worlds: list[World], until_ns: int) -> None:
        """Make the blocks before *until_ns* of several worlds (a sweep's seeds of one
        scenario, none under :meth:`ahead`) block by block in step, each block's IMU samples
        made for all of them at once (emulator.imu.generate_together: each sensor's numbers
        as alone), and so are their boards' SINS frames (Board.frames_together) and their
        nanoLOC networks' reports
        (NanolocNetwork.reports_together: each network's as alone), so
        ``advance(until_ns)`` then only takes each world's events."""
        while True:
            blocks: dict[tuple[int, int], list[World]] = {}
            for w in worlds:
                lo = w._generated_ns
                if lo < min(until_ns, w.duration_ns):
                    blocks.setdefault((lo, min(lo + w.BLOCK_NS, w.duration_ns)), []).append(w)
            if not blocks:
                return
            for (lo, hi), group in blocks.items():
                generate_together([v.imu for w in group for v in w.vehicles], lo, hi)
                written = iter(Board.frames_together([v.board for w in group for v in w.vehicles],
                                                     lo, hi))
                networks = [net for w in group for net in w.networks.values()]
                reports = iter(NanolocNetwork.reports_together(networks, lo, hi))
                for w in group:
                    w._make([next(reports) for _ in w.networks], [next(written) for _ in w.vehicles])

    def made(self, until_ns: int) -> bool:
        """Whether the blocks before *until_ns* are made, so ``advance`` up to it returns at
        once (under the maker, a look at its socket only while they are not known to be)."""
        if self._maker is None:
            return self._generated_ns >= until_ns
        return self._maker.made_ns >= until_ns or self._maker.poll() >= until_ns

    def advance(self, until_ns: int) -> list[Event]:
        """Events with t_ns < until_ns not returned before, in (t_ns, port) order. Blocks
        not made yet are made now (or, while :meth:`ahead` runs, waited for)."""
        if self._maker is not None:
            return self._maker.advance(until_ns)
        until_ns = min(until_ns, self.duration_ns)
        if until_ns <= self._returned_ns:
            return []
        while self._generated_ns < until_ns:
            self._make()
        cut = int(np.searchsorted(self._keys, until_ns * len(self._rank)))
        out, self._events, self._keys = self._events[:cut], self._events[cut:], self._keys[cut:]
        self._returned_ns = until_ns
        return out

    def air(self, until_ns: int, keep: bool = True) -> list[AirFrame]:
        """The air's frames with t_ns < *until_ns* not returned before, in time order, of the
        blocks made so far: a later block's are never earlier. *keep* False: they go by
        and none is returned (nothing in the run takes them now; under the maker none is
        made into an object)."""
        if self._maker is not None:
            return self._maker.air(until_ns, keep)
        until_ns = min(until_ns, self._generated_ns)
        at = self._air_at
        if at == len(self._air) or self._air[at].t_ns >= until_ns:
            return []  # most calls: the loop asks at every wake-up
        cut = bisect.bisect_left(self._air, until_ns, at, key=_T_NS)
        self._air_at = cut
        return self._air[at:cut] if keep else []

    @contextlib.contextmanager
    def ahead(self):
        """While the block runs, a process of its own (emulator.maker) makes the blocks, at
        most one beyond what ``advance`` has taken, so a caller that only takes made blocks
        never waits for one, and nothing of their making runs in the caller's process.
        Enter it before the caller's thread takes a real-time policy: the maker stays an
        ordinary process. From then on the blocks are the maker's: what it made stays
        readable after the block, and what it raised is raised by ``advance``."""
        from .maker import MakerProcess

        if self._maker is not None:
            raise RuntimeError("World.ahead runs once: its maker made the blocks from then on")
        self._maker = MakerProcess(self)
        try:
            yield self
        finally:
            self._maker.stop()

    # -- live faults ------------------------------------------------------------------------
    def _holders(self):
        """(model, what it is, which) for every model that device faults act on."""
        for network in self.networks.values():
            for a in network.anchors:
                yield a, "anchor", {"anchor": a.id}
        for v in self.vehicles:
            yield v.board, "board", {"vehicle": v.number}
            yield v, "router", {"vehicle": v.number}
        for link in [v.uplink for v in self.vehicles] + list(self.downlinks.values()):
            yield link, "link", {}

    @contextlib.contextmanager
    def held(self):
        """The models between two blocks while the block runs (the maker's, while
        :meth:`ahead` runs, stops making). Yields the time events before which are made
        (and fixed): a live fault injected or removed within acts from there on."""
        if self._maker is None:
            yield self._generated_ns
        else:
            with self._maker.held() as made:
                yield made

    def inject(self, fault) -> None:
        """Add device fault *fault* during the run (live control); it acts on the blocks not
        generated yet (call it within :meth:`held`, which says from when): what is generated
        stays as it was. The models it acts on: as for a scenario's faults
        (emulator.faults.acting_on)."""
        if self._maker is not None:
            self._maker.inject(fault)
            return
        for model, kind, which in self._holders():
            if acting_on([fault], kind, **which):
                model.faults = (*model.faults, fault)

    def remove(self, fault) -> None:
        """End live fault *fault* for the blocks not generated yet (within :meth:`held`)."""
        if self._maker is not None:
            self._maker.remove(fault)
            return
        for model, _, _ in self._holders():
            model.faults = tuple(f for f in model.faults if f is not fault)

    @property
    def finished(self) -> bool:
        return self._returned_ns >= self.duration_ns

    # -- truth ------------------------------------------------------------------------------
    def truth(self, t0_ns: int, t1_ns: int, vehicle: int = 1) -> np.ndarray:
        """Vehicle *vehicle*'s true state every millisecond in [t0_ns, t1_ns)
        (emulator.truth.FIELDS; truth.csv is vehicle 1's, truth<n>.csv vehicle n's)."""
        return truth_arrays(self._numbered[vehicle].trajectory, t0_ns, t1_ns)

    def device_truth(self, vehicle: int = 1) -> dict:
        """What vehicle *vehicle*'s devices drew at power-on and its router's join:
        evaluation only."""
        return {"seed": self.seed, **self._numbered[vehicle].device_truth()}
