"""The emulated lab in time: the world's events on the ports' UARTs, in real or virtual time.

Ports. Every declared port (protocols.ports) is emulated by its device model
(emulator.devices): the device gives the port's line its events, and takes what the host
writes to it.

Timeline. Every device writes to its port through an ``emulator.uart.Line``, a model of
its UART (8N1 timing, chunks in ready order, delivered to the PTY whole when the last byte
would have arrived; wrappers between device and line: :meth:`Emulation.wrap`). The world's
events are the ready times of the SINS and nanoLOC lines; on the ``xbee`` line the
coordinator's frames (0x90 for each RF packet, answers to the host) queue the same way,
so an answer never splits a frame in progress; its transmit buffer is bounded
(``coordinator.SERIAL_TX_BUFFER``): an RF packet that arrives when it does not fit is
dropped whole. Times are integer nanoseconds since the run started.

Speeds. ``realtime`` keeps an absolute schedule: the chunk that ends at virtual time t is
written at wall time t0 + t (no drift; a late write never shifts later ones). The loop
sleeps in ``select`` on the attached ports until the deadline (or spins its last moments
where nothing better exists); what the kernel is asked for (real-time priority, timer slack)
is the run's timing mode (emulator.timing), chosen when the run is made and applied to the
thread that runs it for the run only. A FACTOR runs the same schedule at FACTOR x real time;
``max`` runs it as fast as the world can be generated. World events are generated in blocks:
when paced, a second ahead before the clock starts, then by the world's maker process
(World.ahead, emulator.maker: an ordinary process, so no write waits for it to hand over the
GIL) a block ahead of what the loop took; the loop takes made blocks, up to two seconds
ahead, in idle gaps, and waits for one only if it is due now.
The loop wakes for the earliest line deadline (emulator.schedule: a heap, a line re-keyed
when it gets an item or is polled) and waits on the attached ports in one epoll set, so a wake-up costs what is
due and what is readable, not every port's line and file descriptor. The lines due at one
instant (the convoy's cars are copies: their chunks fall due together) are polled and
written in one pass (:meth:`Emulation._write_due`). After writing to the
PTYs the loop yields the CPU once (but under SCHED_FIFO), so a client it woke runs first. Because chunk contents
and times come from the world and the UART model only, the bytes of every port, and their
device times, are identical in every mode and timing mode; only host commands (read from
the PTYs when they arrive) add answers on the ``xbee`` line.

Clients' settings. Every CHECK_NS each attached port's termios are read (the ports in
turns, a few at each wake-up: emulator.schedule.Turns); while a client's
rate, data bits or parity differ from its device's line, the port writes what the client's
UART would read (``uart_rx.ClientView``), with one progress line when that starts or stops.
The recording and the sink get the device's bytes, whatever the clients' settings.

Recording. Each chunk a device emits is recorded, whether or not a client is attached:
``t_device_ns`` = when its first byte leaves the UART, ``t_wall_ns`` (paced runs only) =
monotonic ns since the run started when it was written to the PTY. The recording, and
truth.csv up to the virtual time reached, are flushed every ``FLUSH_S`` of wall time (when
paced, in an idle gap, as world generation is, but never more than ``FLUSH_S`` late; at max
speed also every ``MAX_BLOCK_NS`` of virtual time), so a killed run leaves a replayable
prefix. A write that fails ends the run (``record_error``). A paced run counts, per port,
how late each chunk was written (emulator.timing.Lateness: the loop's wake-up that wrote it,
``t_wall_ns``, minus the chunk's end in device time over the speed), in its summary and the
recording's meta (``lateness``), beside its ``timing`` mode.

The air. The frames the radio hop puts on the air (emulator.world ``air``: each attempt of
the router's packets, lost or received, and the coordinator's MAC ACKs; the coordinator's
``air``: its transmit requests to the router) are handed out in time order as the loop's
virtual time passes them (before a host write stamped later can add one), to the
recording's ``air`` stream (one chunk a PSDU, ``t_device_ns`` its first bit on the air,
``t_wall_ns`` when paced the loop's wake-up that handed it out), to the tap's clients (a
declared stream) and to ``air_sink`` (a
callable given each emulator.radio.AirFrame); at the end the rest up to where the run got.

Faults. The scenario's line faults are wrappers on their port's line (``to_host``) or on
what the host writes to the xbee port (``to_device``: an ``uart.Inbound`` between the PTY
and the coordinator); each draws from its own stream ``faults.line.{n}`` (n counting the
line faults in scenario order). Every injection goes into the run's ledger
(:attr:`Emulation.ledger`, emulator.ledger): into the recording's ``faults.jsonl`` and,
per kind, into the summary's ``faults`` (injections, bytes touched).

Tap. With ports published, ``DIR/tap`` (emulator.tap) gives its clients every chunk as it
is delivered and what the host writes, served from the loop's wait like the control socket;
with no client a chunk costs one check.

Sink. ``sink`` (a callable) is given every chunk as it is delivered, with its device times:
the in-memory run (``lab.run``) takes the lab's bytes from here, with no PTY and no file.
"""
from __future__ import annotations

import contextlib
import dataclasses
import gc
import os
import select
import threading
import time
from typing import Callable

from navtwin.common.limits import SPEEDS, span
from navtwin.common.schema import Invalid, build
from navtwin.protocols import ports as lab_ports
from navtwin.protocols.pcapng import LINKTYPE_IEEE802_15_4_WITHFCS
from navtwin.protocols.recording import FAULTS, FLUSH_S, RecordingWriteError, RecordingWriter

from .control import SOCKET as CONTROL_SOCKET, ControlError, ControlServer, Inject
from .coordinator import Coordinator, Remote, identity_registers
from .devices import DEVICES
from .faults import Fault, LineFault, acting_on
from .ledger import Ledger
from .pty import LinkDir, PtyPort
from .radio import AirFrame
from .rng import stream, vehicles_name
from .schedule import Deadlines, Turns
from .tap import SOCKET as TAP_SOCKET, TapServer
from .timing import Lateness, Mode, TimingError, choose as choose_timing
from .truth import HEADER as TRUTH_HEADER, csv_rows as truth_rows, file_name as truth_file
from .uart import END, Chunk, Drained, Inbound, Irregular, Line, LineWrapper, Marked
from .uart_rx import ClientView, line_framing

SEC = 1_000_000_000
CHECK_NS = 10_000_000  # how often each port is looked at: a new client, its termios
PROGRESS_NS = 3 * SEC  # wall time between progress reports
PACED_BLOCK_NS = 100_000_000  # world generation step when paced, done in idle gaps ...
LOOKAHEAD_NS = 2 * SEC  # ... up to this far ahead of the clock
PREFILL_NS = SEC  # generated before the clock starts
MAX_BLOCK_NS = SEC
FLUSH_NS = int(FLUSH_S * SEC)
TRUTH_STEP_NS = 10 * SEC  # truth rows made at a time: bounds memory when --speed max races ahead
AIR = "air"  # the recording's stream of the radio hop's frames
AIR_DOC = ("the XBee hop on the air: IEEE 802.15.4 PSDUs with FCS (ZigBee NWK and APS data "
           "frames of the router's packets, every attempt, and the coordinator's MAC ACKs); "
           "t_device_ns = the frame's first bit on the air")


class RunError(ValueError):
    """A run that cannot start as asked; the message is one line with the fix."""


def parse_speed(text: str | float) -> float | None:
    """``realtime`` -> 1.0, ``max`` -> None, a number in SPEEDS -> that factor."""
    if text == "realtime":
        return 1.0
    if text == "max":
        return None
    try:
        factor = float(text)
    except ValueError:
        raise RunError(f"speed: {text!r} is not realtime, max or a number; "
                       f"use e.g. realtime, max or 10") from None
    if not SPEEDS[0] <= factor <= SPEEDS[1]:  # also refuses nan
        raise RunError(f"speed: {text!r} must be a positive factor {span(*SPEEDS)}; use e.g. "
                       "10, or max")
    return factor


def speed_name(factor: float | None) -> str:
    return "max" if factor is None else "realtime" if factor == 1.0 else f"{factor:g}"


class Feed:
    """The world's events, generated in blocks of virtual time on demand."""

    def __init__(self, world, end_ns: int, block_ns: int, devices=()) -> None:
        self.world = world
        self.devices = devices  # their own output, beside the world's (emulator.devices)
        self.end_ns = end_ns
        self.block_ns = block_ns
        self.known_ns = 0  # every event with t < known_ns has been taken
        self.cost_ns = 0  # a decaying maximum of the wall time one block takes

    @property
    def exhausted(self) -> bool:
        return self.known_ns >= self.end_ns

    def step(self) -> list:
        """The events of the next block."""
        t = time.monotonic_ns()
        until = min(self.known_ns + self.block_ns, self.end_ns)
        events = self.world.advance(until)
        for device in self.devices:
            events += device.advance(until)
        self.known_ns = until
        self.cost_ns = max(time.monotonic_ns() - t, self.cost_ns * 99 // 100)
        return events

    @property
    def ready(self) -> bool:
        """The next block's events are made (World.ahead): :meth:`step` only takes them."""
        return self.world.made(min(self.known_ns + self.block_ns, self.end_ns))

    def take(self, need_ns: int) -> list:
        """New events; afterwards ``known_ns > need_ns`` or the feed is exhausted."""
        events: list = []
        while not self.exhausted and self.known_ns <= need_ns:
            events += self.step()
        return events


def quick_refusal(scenario) -> str | None:
    """Why :meth:`Emulation.chunks` refuses every run of *scenario* (None: it may take them),
    so a caller can run the timeline without building runs it would refuse."""
    return "a scenario with faults" if scenario.faults else None


@contextlib.contextmanager
def _collector_paused():
    """Python's cyclic garbage collector paused, then as it was: while the quick path makes
    its runs' events (some ten thousand small objects a seed, kept to the end), each of
    the collector's passes would walk all those kept so far, about a tenth of the CPU;
    they hold no cycles, so no garbage waits for it meanwhile. The lines take them from
    the worlds (World.kept), so they are gone when it runs again, not walked once more."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def chunks_together(emulations: list[Emulation], ports) -> list[dict]:
    """:meth:`Emulation.chunks` of several fresh runs (a sweep's seeds of one scenario, in
    one process), their worlds' blocks made in step (World.make_together: each block's IMU
    samples for all of them at once), each run's chunks what it gives alone; Irregular if
    any is refused (then all are spent). Each world keeps its events by port
    (World.by_port), so each line takes its port's events of the whole run at once, in
    the order the timeline puts them (by time, in the order made)."""
    from .world import World

    taken = set(ports)
    for emu in emulations:
        emu._quick(taken)
    with _collector_paused():
        World.make_together([emu.world for emu in emulations], max(emu.end_ns for emu in emulations))
        return [_drained(emu, ports) for emu in emulations]


def _drained(emu: Emulation, ports) -> dict:
    """Each of *ports*' line of the quick run *emu*, given its port's events and drained."""
    own = [ev for device in emu.devices.values() for ev in device.advance(emu.end_ns)]
    got = {}
    for port in ports:
        events = emu.world.kept(port) + [ev for ev in own if ev.port == port]
        if any(ev.marks for ev in events):
            raise Irregular(f"{port}: an item with ledger marks")
        line = emu.lines[port]
        line.put_many(*emu.devices[port].to_line_many(events))
        got[port] = line.drain(emu.end_ns)
    emu._feed.known_ns = emu.reached_ns = emu.end_ns
    return got


class Emulation:
    """One run of a scenario: world, coordinator, UART lines, PTY ports, recording.

    ``Emulation(...)`` creates the ports and links (so clients can open them at once);
    :meth:`run` plays the timeline and returns the summary; :meth:`close` removes the
    links. With ``ports=False`` nothing is published (recording-only runs, in-memory runs
    through ``sink``, and tests).
    """

    def __init__(self, scenario, seed: int | None = None, *, speed: float | None = 1.0,
                 duration_s: float | None = None, link_dir: str | os.PathLike | None = None,
                 record: str | os.PathLike | None = None, ports: bool = True,
                 response_delay_ns: int | None = None, timing: str = "auto",
                 progress: Callable[[str], None] | None = None,
                 sink: Callable[[Chunk], None] | None = None,
                 air_sink: Callable[[AirFrame], None] | None = None, vehicles=None) -> None:
        from .world import World

        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        self.speed = speed
        #: how the paced loop waits (emulator.timing); None at --speed max, which never waits
        self.timing: Mode | None = None
        if speed is not None:
            try:
                self.timing = choose_timing(timing)
            except TimingError as e:
                raise RunError(str(e)) from None
        self.t0_monotonic_ns: int | None = None  # set when the clock starts
        #: the vehicles this run hosts (default all): a worker process hosts some of them
        #: (emulator.workers); each keeps its number, port names and bytes
        # the air's frames have takers only in a recording, a tap (live ports) or an air sink
        self.world = World(scenario, self.seed, vehicles,
                           air=ports or record is not None or air_sink is not None)
        full = self.world.duration_ns
        self.end_ns = full if duration_s is None else int(round(duration_s * SEC))
        if not 0 < self.end_ns <= full:
            raise RunError(f"duration: {duration_s:g} is outside (0, {full / SEC:g}] s, the "
                           f"length of scenario {scenario.name}; pass a duration in that range")
        self.progress = progress
        self.sink = sink
        self.air_sink = air_sink
        #: per coordinator's port (xbee, and xbee<n> with a coordinator per vehicle)
        self.coordinators = self._coordinators(response_delay_ns)
        # every port instance of the scenario's vehicles (protocols.ports), vehicle by vehicle;
        # a device is given its instance as a declaration under the instance's name
        self.devices = {name: DEVICES.get(p.device)(self, dataclasses.replace(p, name=name))
                        for name, p in scenario.instances(v.number for v in self.world.vehicles)}
        self.lateness = Lateness(self.devices)  # paced runs: per port, written how late
        bauds = {name: dev.settings["baud"] for name, dev in self.devices.items()}
        # a recorded run has its entries in faults.jsonl; others keep them in memory
        self.ledger = Ledger(self._record_fault if record is not None else None,
                             keep=record is None, faults=scenario.faults)
        self.lines = {name: Line(name, dev.line_device, ledger=self.ledger)
                      for name, dev in self.devices.items()}
        # what the host writes to each port whose device reads it (the coordinators')
        self.inbounds = {name: Inbound(name, dev.line_device, ledger=self.ledger)
                         for name, dev in self.devices.items() if dev.port.host_writes}
        # the loop's timers: each line's and inbound's next step (emulator.schedule)
        self.line_deadlines = Deadlines(self.lines)
        self.inbound_deadlines = Deadlines(self.inbounds)
        self._line_order = {name: i for i, name in enumerate(self.lines)}  # delivery order
        self._air_from: set[str] = set()  # coordinators the host made send since the last look
        line_faults = [(i, f) for i, f in enumerate(scenario.faults) if f.ACTS_ON == "line"]
        for n, (index, fault) in enumerate(line_faults):
            wrapper = fault.wrapper(stream(self.seed, f"faults.line.{n}"))
            wrapper.kind, wrapper.fault_index = fault.KIND, index
            self.wrap(fault.port, wrapper, fault.direction)
        for port, coordinator in self.coordinators.items():
            coordinator.faults = tuple(acting_on(scenario.faults, "coordinator",
                                                 vehicle=lab_ports.parse(port)[1]))
            for out in coordinator.power_up() + [o for f in coordinator.faults
                                                 for o in self._power_ups(f)]:
                self.lines[port].put(out.t_ns, out.item)
        self.link_dir: LinkDir | None = None
        self.ports: dict[str, PtyPort] = {}
        # the attached ports, waited on in one epoll set: a wake-up costs what is readable,
        # not a select over every port (kept in step every CHECK_NS, and at a hang-up)
        self._attached = select.epoll() if ports else None
        #: what the loop's last sleep saw readable (None: not known, look at everything)
        self._readable: list | None = None
        self._watched: dict[int, PtyPort] = {}  # fd -> port, as registered
        self.views: dict[str, ClientView] = {}  # per port: what the client's UART reads
        self.links: dict[str, str] = {}
        self.control: ControlServer | None = None
        self.tap: TapServer | None = None  # every chunk to its clients (emulator.tap)
        self.live: dict[int, tuple[Fault, LineWrapper | None]] = {}  # id -> live fault
        self._live_ids = 0
        self._now_ns = 0  # the loop's virtual time, for live control
        self.recorder: RecordingWriter | None = None
        try:
            if ports:
                self._publish(link_dir, bauds)
            if record is not None:
                try:
                    self.recorder = self._recorder(record)
                except RecordingWriteError as e:
                    raise RunError(f"record: {e}") from None
                except OSError as e:
                    raise RunError(f"record: {record}: {e.strerror or e}; choose a directory "
                                   f"you can write") from None
        except BaseException:
            self.close()
            raise
        self._feed: Feed | None = None  # the world's events, from prepare()
        self.reached_ns = 0
        self.interrupted = False
        self.record_error: RecordingWriteError | None = None  # the write that ended the run

    def wrap(self, port: str, wrapper: LineWrapper, direction: str = "to_host") -> None:
        """Put *wrapper* between *port*'s device and its line (before :meth:`run`); it sees
        every chunk the device sends (emulator.uart.LineWrapper); with ``direction =
        "to_device"``, every read of what the host writes to the xbee port instead."""
        if port not in self.lines:
            raise RunError(f"no port {port!r} to wrap; use one of {', '.join(self.lines)}")
        if direction == "to_device":
            if port not in self.inbounds:
                raise RunError(f"{port} ignores what the host writes; wrap "
                               f"{' or '.join(self.inbounds)} to_device, or {port} to_host")
            self.inbounds[port].wrap(wrapper)
            self.inbound_deadlines.touch(port)
        else:
            self.lines[port].wrap(wrapper)
            self.line_deadlines.touch(port)
        wrapper.direction = direction

    def _record_fault(self, entry: dict) -> None:
        if self.recorder is not None:
            self.recorder.fault(entry)

    # -- assembly -------------------------------------------------------------------------
    def _publish(self, link_dir, bauds: dict[str, int]) -> None:
        """The PTYs and their links; a failure is a one-line LinkDirError or RunError."""
        self.link_dir = LinkDir(link_dir, tuple(self.devices))
        for name in self.devices:
            try:
                self.ports[name] = PtyPort(name, bauds[name])
            except OSError as e:
                raise RunError(f"cannot create a pseudo-terminal for {name} ({e.strerror}); "
                               f"close some terminals or raise kernel.pty.max") from None
            self.links[name] = str(self.link_dir.link(name, self.ports[name].pts))
            self.views[name] = ClientView(name, line_framing(self.lines[name].device.baud),
                                          notify=self.progress)
        self.control = ControlServer(self.link_dir.path / CONTROL_SOCKET, self._control)
        self.tap = TapServer(self.link_dir.path / TAP_SOCKET, self._tap_hello,
                             lambda: time.monotonic_ns() - self.t0_monotonic_ns)
        self.tap.declare(AIR, LINKTYPE_IEEE802_15_4_WITHFCS, AIR_DOC)

    def _coordinators(self, response_delay_ns: int | None) -> dict[str, Coordinator]:
        """Each coordinator by its port, with the routers that joined it: every vehicle's,
        or with a coordinator per vehicle (the scenario's [xbee] network) its vehicle's."""
        sc, kw = self.scenario, {} if response_delay_ns is None else {"response_delay_ns": response_delay_ns}
        routers = [Remote(identity_registers(r)) for r in sc.routers_for(self.seed)]
        alone = sc.units("coordinator") > 1
        out = {}
        for port, downlink in self.world.downlinks.items():
            n = lab_ports.parse(port)[1]
            radios = sc.radios_for(self.seed, n)  # the routers' MY, the network: from the seed
            coord = identity_registers(radios["coordinator"], CE=1)  # CE: see coordinator.py
            out[port] = Coordinator(coord, routers[n - 1:n] if alone else routers, downlink,
                                    stream(self.seed, vehicles_name(n, "coordinator")), **kw)
        return out

    def _recorder(self, directory) -> RecordingWriter:
        # an existing recording in *directory* is replaced (the CLI checks that it is one,
        # and asks for --overwrite)
        rec = RecordingWriter(directory, replace=True, meta={
            "source": "navtwin emulate", "scenario": self.scenario.name, "seed": self.seed,
            "speed": speed_name(self.speed), "duration_s": self.end_ns / SEC,
            "ports": self.port_settings(), **self._timing_info(),
            "clocks": {"t_device_ns": "ns since the run started when the chunk's first byte "
                                      "leaves the device's UART",
                       "t_wall_ns": "monotonic ns since the run started when the chunk was "
                                    "written to the port (paced runs only)"}})
        self._truth_ns = 0  # truth.csv has the rows before this
        self._flush_cost_ns = 0  # a decaying maximum of the wall time one flush takes
        try:
            rec.stream(AIR, LINKTYPE_IEEE802_15_4_WITHFCS, AIR_DOC)  # there, empty or not
            rec.write_file("scenario.toml", self.scenario.to_toml().encode())
            for v in self.world.vehicles:
                rec.file(truth_file(v.number)).append(TRUTH_HEADER)
            rec.file(FAULTS)  # the ledger: there, and empty, even when no fault acts
        except BaseException:
            rec.close()
            raise
        return rec

    def _flush(self, rec: RecordingWriter, truth_until_ns: int) -> None:
        """Append truth.csv's rows up to *truth_until_ns* and write everything buffered."""
        if rec.error is not None:
            return  # it ended the run; nothing more is written
        t = time.monotonic_ns()
        while True:
            t1 = min(self._truth_ns + TRUTH_STEP_NS, truth_until_ns)
            if t1 > self._truth_ns:
                for v in self.world.vehicles:
                    rec.file(truth_file(v.number)).append(
                        truth_rows(self.world.truth(self._truth_ns, t1, v.number)))
                self._truth_ns = t1
            rec.flush()
            if t1 >= truth_until_ns:
                break
        self._flush_cost_ns = max(time.monotonic_ns() - t, self._flush_cost_ns * 99 // 100)

    def port_settings(self) -> dict[str, dict]:
        """Each port's settings, as a recording's meta keeps them."""
        return {name: dict(dev.settings) for name, dev in self.devices.items()}

    def _tap_hello(self) -> dict:
        """The run, for a client of the tap that comes now (emulator.tap)."""
        return {"scenario": self.scenario.name, "seed": self.seed,
                "speed": speed_name(self.speed), "duration_s": self.end_ns / SEC,
                "ports": self.port_settings(),
                "offsets": {name: line.delivered for name, line in self.lines.items()}}

    def info(self) -> dict:
        """The ``ready`` line: ports (stable links), pts paths, scenario, seed, speed."""
        return {"ready": True, "ports": dict(self.links),
                "pts": {n: p.pts for n, p in self.ports.items()},
                "scenario": self.scenario.name, "seed": self.seed, "speed": speed_name(self.speed),
                "duration_s": self.end_ns / SEC, **self._timing_info(),
                "link_dir": str(self.link_dir.path) if self.link_dir else None,
                "control": str(self.control.path) if self.control else None,
                "tap": str(self.tap.path) if self.tap else None,
                "pid": os.getpid()}

    def _timing_info(self) -> dict:
        """``timing``: the paced run's mode (emulator.timing); none at --speed max."""
        return {"timing": self.timing.name} if self.timing is not None else {}

    # -- the loop ---------------------------------------------------------------------------
    def run(self, stop: threading.Event | None = None,
            start_monotonic_ns: int | None = None) -> dict:
        """Play the timeline until the end or until *stop* is set; returns :meth:`summary`.
        *start_monotonic_ns*: scenario time 0 on CLOCK_MONOTONIC (default: once
        :meth:`prepare` is done), so worker processes share one schedule."""
        stop = stop or threading.Event()
        paced = self.speed is not None
        feed = self.prepare()
        t0 = self.t0_monotonic_ns = start_monotonic_ns or time.monotonic_ns()
        self._turns = Turns(self.ports.values(), CHECK_NS, t0)  # every port at the clock's start
        next_progress = t0 + PROGRESS_NS if self.progress else END
        next_flush = t0 + FLUSH_NS if self.recorder is not None else END
        try:
            # the maker process first: it must not inherit the loop's real-time policy
            with self.world.ahead() if paced else contextlib.nullcontext(), \
                    self.timing.applied() if paced else contextlib.nullcontext():
                self._loop(stop, feed, paced, t0, next_progress, next_flush)
        except RecordingWriteError as e:
            self.record_error = e
            self.interrupted = True
        return self.summary()

    def chunks(self, ports) -> dict[str, Drained]:
        """The quick path of an in-memory run (lab.run): what :meth:`run` at --speed max would
        hand a sink for each port instance in *ports*, as the chunks' bytes end to end and
        each one's size and start time, in the port's order, the lines timed in one pass each
        (emulator.uart Line.drain); the world keeps no events of the other ports
        (World.by_port). Only for a fresh run at --speed
        max with no PTY and no recording, of a scenario without faults (wrappers, marks and
        a coordinator's power cuts are the timeline's: uart.Irregular, as for whatever else
        drain refuses; the emulation is then spent and the caller runs a fresh one). Equal
        to the sink's: tests/emulator/test_quick_lines.py. :func:`chunks_together` runs
        several seeds' at once."""
        return chunks_together([self], ports)[0]

    def _quick(self, taken: set) -> None:
        """The run as :meth:`chunks` takes it, its refusals checked first: its world keeps
        the events of the ports *taken*, by port; its feed is spent."""
        if self.speed is not None or self.ports or self.recorder is not None \
                or self._feed is not None:
            raise Irregular("only a fresh unpaced run without ports or a recording")
        if (reason := quick_refusal(self.scenario)) is not None:
            raise Irregular(reason)
        self.world.by_port(taken)
        self._feed = Feed(self.world, self.end_ns, MAX_BLOCK_NS, tuple(self.devices.values()))

    def prepare(self) -> Feed:
        """The world's events before the clock starts (paced: its first second), once; a
        worker does it before its ready line, so the common start need not wait for it."""
        if self._feed is None:
            paced = self.speed is not None
            self._feed = Feed(self.world, self.end_ns, PACED_BLOCK_NS if paced else MAX_BLOCK_NS,
                              tuple(self.devices.values()))
            self._enqueue(self._feed.take(PREFILL_NS if paced else 0))
            if paced:  # what exists now lives for the run: keep full collections from walking it
                gc.collect()
                gc.freeze()
        return self._feed

    def _loop(self, stop, feed: Feed, paced: bool, t0: int, next_progress: int,
              next_flush: int) -> None:
        vt = 0  # virtual time of the loop (max speed)
        while not stop.is_set():
            wall = time.monotonic_ns()
            now = int((wall - t0) * self.speed) if paced else vt
            if self.ports:
                self._service(now, wall)
            self._enqueue(feed.take(now))
            self._now_ns = now
            self._to_device(now)
            self._on_air(now, wall - t0 if paced else None)  # before host writes stamped now
            if not paced:  # everything known so far, in one go
                now = END if feed.exhausted else feed.known_ns
            delivered = self._write_due(now, feed.known_ns, wall - t0 if paced else None)
            if delivered and paced and self.ports and self.timing.yields:
                # let a client woken by these writes run before we go on
                os.sched_yield()
            self.reached_ns = max(self.reached_ns, min(now, self.end_ns))
            if wall >= next_progress:
                self._report(wall - t0)
                next_progress = wall + PROGRESS_NS
            target, inbound = self.line_deadlines.next(), self.inbound_deadlines.next()
            if inbound is not None and (target is None or inbound < target):
                target = inbound
            if not feed.exhausted:
                target = feed.known_ns if target is None else min(target, feed.known_ns)
            if target is None or (target >= self.end_ns
                                  and not any(l.busy(self.end_ns) for l in self.lines.values())):
                self.reached_ns = self.end_ns
                break
            if self.recorder is not None and self._flush_due(wall, next_flush, t0, target):
                self._flush(self.recorder, self.reached_ns)
                next_flush = time.monotonic_ns() + FLUSH_NS
                if paced:
                    continue  # the flush took time: look at the clock again
            if not paced:
                vt = max(vt, min(now, target))
                continue
            deadline = t0 + int(target / self.speed)
            if (feed.known_ns < now + LOOKAHEAD_NS and not feed.exhausted and feed.ready
                    and deadline - time.monotonic_ns()
                    > 2 * feed.cost_ns + 2 * self.timing.spin_ns):
                self._enqueue(feed.step())  # take what the maker made while there is time to spare
                continue
            self._wait(deadline, min(self._turns.next_ns if self.ports else END, next_progress))
        else:
            self.interrupted = True

    def _flush_due(self, wall: int, next_flush: int, t0: int, target: int) -> bool:
        if self.speed is None:  # also per block of virtual time: a failing disk loses one
            return wall >= next_flush or self.reached_ns >= self._truth_ns + MAX_BLOCK_NS
        idle_ns = t0 + int(target / self.speed) - wall  # until the next write is due
        return wall >= next_flush and (wall >= next_flush + FLUSH_NS
                                       or idle_ns > 2 * self._flush_cost_ns
                                       + 2 * self.timing.spin_ns)

    def _wait(self, deadline: int, check_at: int) -> None:
        """Sleep until *deadline* (monotonic ns) or a client writes; spin the last
        ``spin_ns`` of the timing mode, never longer (a SCHED_FIFO thread must sleep)."""
        fds = [self._attached.fileno()] if self.ports else []
        if self.control is not None:
            fds += self.control.fds() + self.tap.fds()
        now = time.monotonic_ns()
        spin_from = deadline - self.timing.spin_ns
        sleep_until = min(spin_from, check_at)
        if sleep_until > now:
            r, _, _ = select.select(fds, [], [], (sleep_until - now) / SEC)
            now = time.monotonic_ns()
            self._readable = r
        else:
            r = []
        if r or now < spin_from:
            return  # input, or time to look at the ports: the loop comes back here
        while time.monotonic_ns() < deadline:
            pass

    def _service(self, now: int, wall: int) -> None:
        """Read what clients wrote (stamped *now*) and notice clients coming and going, and
        (each port every CHECK_NS, in turns: emulator.schedule.Turns) their termios settings.
        A paced loop looks only at what its last sleep saw readable: what comes later wakes
        the next sleep at once (each system call here costs the loop's time); at --speed max,
        which never sleeps, at everything."""
        readable = self._readable
        if self.speed is not None:
            self._readable = []
        if readable is None or self._attached.fileno() in readable:
            for fd, _ in self._attached.poll(0):
                port = self._watched.get(fd)
                if port is not None:
                    self._host_bytes(port, now)
                    if not port.attached:  # it read the hang-up
                        self._unwatch(port)
        if self.control is not None:
            sockets = select.select(self.control.fds() + self.tap.fds(), [], [], 0)[0] \
                if readable is None else readable
            self.control.serve(sockets)
            self.tap.serve(sockets)
        views, watched = self.views, self._watched
        for port in self._turns.due(wall):
            if not port.attached:
                port.check()
                # what a client wrote before it was noticed (it may even have gone again):
                # a real line delivers it all the same
                self._host_bytes(port, now)
            if port.attached:
                views[port.name].settle(*port.client_framing())
                if port.fd not in watched:
                    watched[port.fd] = port
                    self._attached.register(port.fd, select.EPOLLIN)
            else:
                views[port.name].settle(None, 0)
                if watched.get(port.fd) is port:
                    self._unwatch(port)

    def _unwatch(self, port: PtyPort) -> None:
        """Stop waiting on *port* (detached, unplugged or replugged): a detached master is
        readable forever."""
        for fd in [fd for fd, p in self._watched.items() if p is port]:
            del self._watched[fd]
            with contextlib.suppress(OSError):  # closed: the kernel dropped it already
                self._attached.unregister(fd)

    def _host_bytes(self, port: PtyPort, now: int) -> None:
        data = port.read()
        if data and self.tap.clients:
            self.tap.chunk(port.name, "to_device", now, data)
        if data and port.name in self.inbounds:
            self.inbounds[port.name].put(now, data)
            self.inbound_deadlines.touch(port.name)
            self._to_device(now)
        # the SINS board and the nanoLOC gateway ignore what the host sends them

    def _to_device(self, now: int) -> None:
        """Give each device what the host wrote, as its to_device faults let it through
        (the inbounds due by *now*)."""
        for name in self.inbound_deadlines.due(now):
            view, device, line = self.views.get(name), self.devices[name], self.lines[name]
            for t, data in self.inbounds[name].poll(now):
                if view is not None:  # read by the device's UART at its rate
                    data = view.heard(t, data, line_framing(device.line_device.baud))
                self._catch_up(name, t)
                for t_ns, item in device.host(t, data):
                    line.put(t_ns, item)
                self.line_deadlines.touch(name)
                self._air_from.add(name)

    def _catch_up(self, port: str, t_ns: int) -> None:
        """Line *port*'s steps due by *t_ns* taken before a change at *t_ns* from outside
        the timeline (emulator.uart.Line: the loop does not wake when a chunk starts)."""
        self.lines[port].catch_up(t_ns, self._feed.known_ns if self._feed else 0, self.end_ns)
        self.line_deadlines.touch(port)

    def _enqueue(self, events: list) -> None:
        """Put the world's *events* on their ports' lines."""
        devices, lines, touch = self.devices, self.lines, self.line_deadlines.touch
        for ev in events:
            t_ns, item = devices[ev.port].to_line(ev)
            lines[ev.port].put(t_ns, Marked(item, ev.marks) if ev.marks else item)
            touch(ev.port)

    def _write_due(self, now: int, known_ns: int, wall_ns: int | None) -> bool:
        """Poll the lines due by *now*, in the lab's port order, and deliver the chunks they
        end, each line's in its order; whether any was. The convoy's cars are copies, so
        their lines fall due together: a burst of N writes, each costing what is written
        (the lookups are made once a burst)."""
        due = self.line_deadlines.due(now)
        if len(due) > 1:
            due.sort(key=self._line_order.__getitem__)
        lines, end_ns, deliver, delivered = self.lines, self.end_ns, self._deliver, False
        for name in due:
            for chunk in lines[name].poll(now, known_ns, end_ns):
                deliver(chunk, wall_ns)
                delivered = True
        return delivered

    def _deliver(self, chunk: Chunk, wall_ns: int | None) -> None:
        name = chunk.port
        if wall_ns is not None:
            self.lateness.add(name, wall_ns - int(chunk.end_ns / self.speed))
        port = self.ports.get(name)
        if port is not None:  # the recording below keeps the device's bytes, not this view
            port.write(self.views[name].view(chunk.start_ns, chunk.data, line_framing(chunk.baud)))
        if self.recorder is not None:
            self.recorder.port(chunk.port).write(chunk.data, chunk.start_ns, wall_ns)
        if self.sink is not None:
            self.sink(chunk)
        if self.tap is not None and self.tap.clients:
            self.tap.chunk(chunk.port, "to_host", chunk.start_ns, chunk.data, wall_ns)

    def _on_air(self, until_ns: int, wall_ns: int | None) -> None:
        """Hand the air's frames before *until_ns* (and the run's end), the world's and the
        coordinator's, to the recording and the air sink in time order. *until_ns* is the
        loop's time, before which no host write comes any more, so no frame comes later
        that is earlier than one handed out. With none of them taking frames (no tap client
        now), the world's go by unmade."""
        until_ns = min(until_ns, self.end_ns)
        mine = []
        # only the host's requests put frames on a coordinator's air (most wake-ups: none)
        asked = [p for p in self.coordinators if p in self._air_from] if self._air_from else ()
        for port in asked:
            coordinator = self.coordinators[port]
            if not coordinator.air:
                self._air_from.discard(port)
                continue
            mine += [f for f in coordinator.air if f.t_ns < until_ns]
            coordinator.air = [f for f in coordinator.air if f.t_ns >= until_ns]
        taken = self.recorder is not None or self.air_sink is not None or bool(
            self.tap is not None and self.tap.clients)
        frames = self.world.air(until_ns, taken) + mine
        if not frames:
            return
        if mine:
            frames.sort(key=lambda f: f.t_ns)  # the world's come in order
        recorded = None if self.recorder is None else \
            self.recorder.stream(AIR, LINKTYPE_IEEE802_15_4_WITHFCS, AIR_DOC)
        for frame in frames:
            if recorded is not None:
                recorded.write(frame.psdu, frame.t_ns, wall_ns)
            if self.air_sink is not None:
                self.air_sink(frame)
            if self.tap is not None and self.tap.clients:
                self.tap.stream(AIR, frame.t_ns, frame.psdu)

    def _report(self, elapsed_ns: int) -> None:
        v = self.reached_ns / SEC
        self.progress(f"{self.scenario.name}: {v:.1f} / {self.end_ns / SEC:g} s "
                      f"({v / (elapsed_ns / SEC):.0f}x real time)")
        for view in self.views.values():
            if view.client is not None:
                self.progress(view.status())

    # -- live control (emulator.control) ------------------------------------------------------
    def _control(self, op: str, args) -> dict:
        """Do control request *op* with *args*, its table of control.OPS (types checked)."""
        return getattr(self, f"_op_{op}")(args)

    def _op_status(self, args) -> dict:
        for n in [n for n, (f, _) in self.live.items() if f.end_s * SEC <= self._now_ns]:
            self._end_live(n)  # over: no longer live
        return {"virtual_s": self._now_ns / SEC, "duration_s": self.end_ns / SEC,
                "t0_monotonic_ns": self.t0_monotonic_ns, "ports": {
                    n: {"plugged": p.plugged, "attached": p.attached, "pts": p.pts,
                        "link": self.links.get(n)} for n, p in self.ports.items()},
                "faults": [self._live_entry(i) for i in self.live],
                "tap": self.tap.status() if self.tap else None}

    def _live_entry(self, n: int) -> dict:
        fault, _ = self.live[n]
        return {"id": n, "kind": fault.KIND, "start_s": fault.start_s, "end_s": fault.end_s}

    def _op_fault(self, args) -> dict:
        """A fault from now on: a line fault from the next chunk, a device fault from the
        world's next block (what is generated, up to ~2 s ahead when paced, stays). It is
        built and applied before the reply, so a fault the lab cannot take is refused."""
        spec, duration = args.fault, args.duration_s
        if {"start_s", "end_s"} & set(spec):
            raise ControlError('give "fault" as {"kind": ..., settings} without start_s/end_s '
                               '(a live fault starts now; "duration_s" sets its length)')
        try:
            kind = type(build(Fault, spec, (("fault", 0),)))  # the settings, checked
        except Invalid as e:
            raise ControlError(str(e)) from None
        # a line or coordinator fault acts on what has not been sent: from now; a device
        # fault on what the world's models have not made, and they stay between two blocks
        # until it is on them (only they: holding the world finishes the block in progress)
        on_world = kind.ACTS_ON not in ("line", "coordinator")
        with self.world.held() if on_world else contextlib.nullcontext(self._now_ns) as start:
            try:
                end = {} if duration is None else {"end_s": start / SEC + duration}
                fault = build(Fault, {**spec, "start_s": start / SEC, **end}, (("fault", 0),))
            except Invalid as e:
                raise ControlError(str(e)) from None
            if (problem := self.scenario.fault_problem(fault)) is not None:
                raise ControlError(f"[fault] {problem[0]} {problem[1]}")
            if fault.ACTS_ON == "coordinator" and duration is None:
                raise ControlError("a live coordinator_reset needs duration_s: the radio powers up "
                                   "at its end")
            self._live_ids += 1
            wrapper = None
            if isinstance(fault, LineFault):
                wrapper = fault.wrapper(stream(self.seed, f"faults.live.{self._live_ids}"))
                wrapper.kind, wrapper.fault_index = fault.KIND, None  # live: in no [[faults]]
                if fault.direction == "to_host":
                    self._catch_up(fault.port, start)
                self.wrap(fault.port, wrapper, fault.direction)
            elif fault.ACTS_ON == "coordinator":
                port = lab_ports.instance(lab_ports.XBEE.name, fault.vehicle)
                self._catch_up(port, start)
                self.coordinators[port].faults += (fault,)
                for out in self._power_ups(fault):
                    self.lines[port].put(out.t_ns, out.item)
                self.line_deadlines.touch(port)
            else:
                self.world.inject(fault)
            self.live[self._live_ids] = (fault, wrapper)
        return self._live_entry(self._live_ids)

    #: ``reset``: the device -> the fault kind that power-cycles it
    RESETS = {"board": "board_reset", "coordinator": "coordinator_reset"}
    RESET_S = 0.5  # a brown-out and the boot after it

    def _op_reset(self, args) -> dict:
        kind = self.RESETS.get(args.device)
        if kind is None:
            raise ControlError(f"no device {args.device[:40]!r} to reset; use one of "
                               f"{', '.join(self.RESETS)}")
        whose = {} if args.vehicle is None else {"vehicle": args.vehicle}
        return self._op_fault(Inject({"kind": kind, **whose}, self.RESET_S if args.duration_s is None
                                     else args.duration_s))

    def _power_ups(self, fault) -> list:
        """The coordinator's power-up at the end of each episode of coordinator fault *fault*
        (its first frame marked for the ledger)."""
        coordinator = self.coordinators[lab_ports.instance(lab_ports.XBEE.name, fault.vehicle)]
        out, t = [], fault.next_active(0)
        while t is not None and t < self.end_ns:
            up = fault.episode_end(t)
            first, *rest = coordinator.power_up(up)
            mark = {"kind": fault.KIND, "fault": fault, "t_ns": up, "off_ns": up - t}
            out += [first._replace(item=Marked(first.item, (mark,))), *rest]
            t = fault.next_active(up)
        return out

    def _op_clear(self, args) -> dict:
        ids = list(self.live) if args.id is None else [args.id]
        if any(n not in self.live for n in ids):
            raise ControlError(f"no live fault {args.id}; the live ones are {list(self.live)}")
        for n in ids:
            self._end_live(n)
        return {"cleared": ids}

    def _end_live(self, n: int) -> None:
        fault, wrapper = self.live.pop(n)
        if wrapper is not None:
            to_device = wrapper.direction == "to_device"
            if not to_device:
                self._catch_up(fault.port, self._now_ns)
            (self.inbounds if to_device else self.lines)[fault.port].wrappers.remove(wrapper)
            (self.inbound_deadlines if to_device else self.line_deadlines).touch(fault.port)
        elif fault.ACTS_ON != "coordinator":  # that one ends at its end: it powers up then
            with self.world.held():
                self.world.remove(fault)

    def _port(self, args) -> PtyPort:
        port = self.ports.get(args.port)
        if port is None:
            raise ControlError(f"no port {args.port[:40]!r}; use one of {', '.join(self.ports)}")
        return port

    def _op_unplug(self, args) -> dict:
        port = self._port(args)
        self._unwatch(port)
        port.unplug()
        self.link_dir.unlink(port.name)
        self.links.pop(port.name, None)
        return {"port": port.name, "plugged": False}

    def _op_replug(self, args) -> dict:
        port = self._port(args)
        if not port.plugged:
            self._unwatch(port)
            port.replug()
            self.links[port.name] = str(self.link_dir.link(port.name, port.pts))
        return {"port": port.name, "plugged": True, "pts": port.pts}

    # -- results ----------------------------------------------------------------------------
    def summary(self) -> dict:
        ports = {}
        for name, line in self.lines.items():
            entry = {"frames": line.chunks, "bytes": line.bytes}
            entry.update(self.devices[name].stats())
            if name in self.ports:
                entry.update(self.ports[name].stats())
                entry.update(self.views[name].stats())
            if self.timing is not None:
                entry["late"] = self.lateness.histograms()[name]
            ports[name] = entry
        return {"done": True, "scenario": self.scenario.name, "seed": self.seed,
                "speed": speed_name(self.speed), **self._timing_info(),
                "virtual_s": self.reached_ns / SEC, "interrupted": self.interrupted, "ports": ports,
                "faults": self.ledger.totals(),  # per kind: injections, bytes touched
                # scenario time 0 on this machine's CLOCK_MONOTONIC (paced runs), so a host on
                # the same machine can put its estimates on the scenario's time for evaluation
                "t0_monotonic_ns": self.t0_monotonic_ns if self.speed is not None else None}

    def close(self) -> None:
        """Finish the recording (truth.csv up to where the run got), close ports, remove links."""
        if getattr(self, "reached_ns", None) is not None:  # it ran (close may come twice)
            try:
                self._on_air(self.reached_ns, None)  # the frames the loop had not reached
            except RecordingWriteError as e:
                self.record_error = self.record_error or e
        rec, self.recorder = getattr(self, "recorder", None), None
        if rec is not None:
            rec.meta["interrupted"] = self.interrupted
            rec.meta["virtual_s"] = self.reached_ns / SEC
            if self.timing is not None:
                rec.meta["lateness"] = self.lateness.histograms()
            for finish in (lambda: self._flush(rec, max(self.reached_ns, 1)), rec.close):
                try:
                    finish()
                except RecordingWriteError as e:  # the first failure is the one to report
                    self.record_error = self.record_error or e
        if getattr(self, "control", None) is not None:
            self.control.close()
            self.control = None
        if getattr(self, "tap", None) is not None:
            self.tap.close()
            self.tap = None
        for port in self.ports.values():
            port.close()
        if getattr(self, "_attached", None) is not None:
            self._attached.close()
        if self.link_dir is not None:
            self.link_dir.close()
            self.link_dir = None

    def __enter__(self) -> "Emulation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
