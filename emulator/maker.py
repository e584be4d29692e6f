"""The world's blocks made by a process of its own while a paced run's loop writes (issue 22).

A paced run's loop writes each chunk at its deadline under the best timing mode it is allowed
(emulator.timing); meanwhile the world's next blocks must be made (about 8 ms of CPU a
vehicle-second: the IMU's draws, the radio hop, the networks). Made by a thread of the same
process, they shared the interpreter's lock with the loop: an ordinary thread that the kernel
preempts while it holds the GIL holds up the loop woken at a deadline by up to a time slice,
whatever the loop's priority. A process has an interpreter lock of its own: with it the
emulator's writes 1 ms late or more fell 25-80x, and at 50 cars the median port's p99 from
1.4-1.55x the bare PTY pair's to 0.84-1.04x (``navtwin bench scale`` and ``bench
emulator-writes``, the thread and the process run alternately: docs/performance.md, "The
world's blocks in a process of their own").

:class:`MakerProcess` forks when the paced run starts (:meth:`World.ahead`). The child is the
world as it stands, its models, random streams and the events made so far, and from then on
it makes every block, each with the World's own ``advance`` and ``air``; the parent's World
gives what the child sends (``advance``, ``air``, ``made``, ``held``, ``inject``,
``remove``). So the events are those the World makes in one process, in the same order
(tests/emulator/test_maker.py); only where they are made moves.

Transport. Parent and child share a Unix socket pair (SOCK_SEQPACKET: one message a note
or a command). Each block's events and air frames go to a memory file of the child's
(``memfd_create``: nothing on a file system, nothing left behind by a process killed
outright): the fixed fields as arrays, the payloads as one blob, the ledger marks as JSON
with each fault as its number (the scenario's ``[[faults]]`` in order, then the live ones in
the order the parent injected them). A 16-byte note carries the file's descriptor to the
parent (SCM_RIGHTS), which reads it in the loop's idle time (``made``) or when it needs
it, and makes Event objects only for what ``advance`` returns (a second of fifty vehicles
is 12 000 events: made at once, a 15 ms pause of the loop). The child makes at most one
block beyond what the parent has taken, as the thread did; the parent says how far it has
taken.

Live device faults: ``held`` asks the child to stop between two blocks and says from when
the models are not made yet; ``inject`` and ``remove`` pass the fault (its settings, which
build it again) and are applied by the child before it makes the next block.

The child closes every inherited descriptor but its socket (a PTY master left open there
would keep a client from ever seeing its port hang up), ignores SIGINT (the terminal's
Ctrl-C is the parent's to handle), dies with its parent (``PR_SET_PDEATHSIG``) and ends
when the parent closes its end. The channels' counts of dropped packets, kept by the
child's models, come with each block.
"""
from __future__ import annotations

import bisect
import collections
import contextlib
import itertools
import json
import os
import select
import signal
import socket
import struct
import time
import traceback

import numpy as np

from navtwin.common.schema import build, plain

from .events import Event, RfPacket
from .faults import Fault
from .radio import AirFrame
from .timing import die_with_parent

_NOTE = struct.Struct("<qq")  # (what, value): every message starts with one
MORE, HOLD, RELEASE, INJECT, REMOVE = 1, 2, 3, 4, 5  # commands: parent -> child
BLOCK, HELD, FAILED = 1, 2, 3  # notes: child -> parent
_EVENT = np.dtype([("t", "<i8"), ("rank", "<i8"), ("packet", "<i8"), ("src64", "<u8"),
                   ("src16", "<i8"), ("options", "<i8"), ("end", "<i8")])
_AIR = np.dtype([("t", "<i8"), ("end", "<i8")])
STOP_S = 5.0  # a child that has not ended this long after the end of its commands is killed


class MakerError(RuntimeError):
    """The maker process failed (what it raised, as text) or has stopped."""


class MakerProcess:
    """The parent's side: the blocks the child makes, as the World's methods give them."""

    def __init__(self, world) -> None:
        self.world = world
        self._names = list(world._rank)  # rank -> port name
        self._faults = list(world.scenario.faults)  # number -> fault, live ones appended
        self.made_ns = world._returned_ns  # the child sends from here
        self._events: collections.deque = collections.deque()  # received blocks not all returned
        self._air: collections.deque = collections.deque()
        self._held_at: int | None = None
        mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:  # the child: never returns
            code = 1
            try:
                mine.close()
                code = _child(world, parent, theirs)
            finally:
                os._exit(code)
        theirs.close()
        self.pid, self._sock = pid, mine
        self.stopped = False

    # -- the World's methods ----------------------------------------------------------------
    def advance(self, until_ns: int) -> list:
        w = self.world
        until_ns = min(until_ns, w.duration_ns)
        if until_ns <= w._returned_ns:
            return []
        while self.made_ns < until_ns:
            self._receive(wait=True)
        out: list = []
        q = self._events
        while q:
            out += q[0].events(until_ns, self._names, self._faults)
            if not q[0].left:
                q.popleft()
            else:
                break
        w._returned_ns = until_ns
        self._send(MORE, until_ns)
        return out

    def air(self, until_ns: int, keep: bool = True) -> list:
        # of the blocks taken so far (the loop asks at every wake-up: no system call here)
        until_ns = min(until_ns, self.made_ns)
        out: list = []
        q = self._air
        while q:
            out += q[0].frames(until_ns, keep)
            if not q[0].left:
                q.popleft()
            else:
                break
        return out

    def poll(self) -> int:
        """Blocks made so far (the notes that came are taken)."""
        self._receive(wait=False)
        return self.made_ns

    @contextlib.contextmanager
    def held(self):
        self._send(HOLD, 0)
        self._held_at = None
        while self._held_at is None:
            self._receive(wait=True)
        try:
            yield self._held_at
        finally:
            self._send(RELEASE, 0)

    def inject(self, fault) -> None:
        self._faults.append(fault)
        spec = json.dumps({"n": len(self._faults) - 1, "fault": {"kind": fault.KIND, **plain(fault)}})
        self._send(INJECT, len(spec.encode()), spec.encode())

    def remove(self, fault) -> None:
        self._send(REMOVE, next(n for n, f in enumerate(self._faults) if f is fault))

    def stop(self) -> None:
        """End the child (what it sent and the parent took stays readable)."""
        if self.stopped:
            return
        self.stopped = True
        self._sock.close()  # the child's end of file; blocks it sent and nobody took go too
        deadline = time.monotonic() + STOP_S
        while os.waitpid(self.pid, os.WNOHANG) == (0, 0):
            if time.monotonic() > deadline:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
                break
            time.sleep(0.01)

    # -- transport --------------------------------------------------------------------------
    def _send(self, what: int, value: int, payload: bytes = b"") -> None:
        if self.stopped:
            raise MakerError("the world's maker process has stopped")
        try:
            self._sock.send(_NOTE.pack(what, value) + payload)
        except OSError as e:  # it died: what it said last, if it said why, is in _receive
            self._receive(wait=False)
            raise MakerError(f"the world's maker process ended unexpectedly ({e})") from None

    def _receive(self, wait: bool) -> None:
        """Take the notes that have come (*wait*: at least one)."""
        if self.stopped:
            if wait:
                raise MakerError("the world's maker process has stopped before making the "
                                 "events asked for")
            return
        while wait or select.select([self._sock], [], [], 0)[0]:
            note, fds, _, _ = socket.recv_fds(self._sock, _NOTE.size, 1)
            if not note:
                raise MakerError("the world's maker process ended unexpectedly")
            self._note_of(*_NOTE.unpack(note), *fds)
            wait = False

    def _note_of(self, what: int, value: int, fd: int | None = None) -> None:
        if what == HELD:
            self._held_at = value
            return
        try:
            data = os.pread(fd, os.fstat(fd).st_size, 0)
        finally:
            os.close(fd)
        if what == FAILED:
            raise MakerError("the world's maker process failed:\n" + data.decode(errors="replace"))
        head, events, air = _Block.parse(data)
        self._events.append(events)
        self._air.append(air)
        for port, dropped in head["dropped"].items():
            self.world.channels[port].dropped = dropped
        self.made_ns = head["to"]


class _Events:
    """A block's events, made into Event objects as they are returned."""

    def __init__(self, fields: np.ndarray, blob: bytes, marks: dict) -> None:
        self.fields, self.blob, self.marks, self.at = fields, blob, marks, 0

    @property
    def left(self) -> bool:
        return self.at < len(self.fields)

    def events(self, until_ns: int, names: list, faults: list) -> list:
        """The Event objects of those with t_ns < *until_ns* not taken yet: made column by
        column (the loop's CPU per event is the cost of the maker process to the loop)."""
        lo = self.at
        hi = lo + int(np.searchsorted(self.fields["t"][lo:], until_ns))
        self.at = hi
        if hi == lo:
            return []
        f = self.fields[lo:hi]
        ends = f["end"].tolist()
        blob = self.blob
        data = [blob[s:e] for s, e in zip([int(self.fields["end"][lo - 1]) if lo else 0, *ends], ends)]
        for j in np.flatnonzero(f["packet"]).tolist():
            data[j] = RfPacket(int(f["src64"][j]), int(f["src16"][j]), int(f["options"][j]), data[j])
        out = list(map(Event, f["t"].tolist(), [names[r] for r in f["rank"].tolist()], data,
                       itertools.repeat((), hi - lo)))
        for i, m in self.marks.items():
            if lo <= i < hi:
                out[i - lo] = out[i - lo]._replace(marks=tuple(
                    {**mark, "fault": faults[mark["fault"]]} for mark in m))
        return out


class _Air:
    """A block's air frames."""

    def __init__(self, fields: np.ndarray, blob: bytes) -> None:
        self.fields, self.blob, self.at = fields, blob, 0
        self.t = fields["t"].tolist()

    @property
    def left(self) -> bool:
        return self.at < len(self.fields)

    def frames(self, until_ns: int, keep: bool = True) -> list:
        lo = self.at
        hi = bisect.bisect_left(self.t, until_ns, lo)  # a list: asked at every wake-up
        self.at = hi
        if hi == lo or not keep:
            return []
        start = [int(self.fields["end"][lo - 1]) if lo else 0] + self.fields["end"][lo:hi - 1].tolist()
        return [AirFrame(t, self.blob[s:e]) for (t, e), s in zip(self.fields[lo:hi].tolist(), start)]


class _Block:
    """One block on file: a JSON line (from, to, counts, marks, channels' drops), the events'
    fields, the air frames' fields, the events' payloads, the air frames' PSDUs."""

    @staticmethod
    def write(f, lo: int, hi: int, events: list, air: list, rank: dict, number: dict,
              channels: dict) -> None:
        fields = np.zeros(len(events), _EVENT)
        payloads, marks, end = [], {}, 0
        rows = []
        for i, e in enumerate(events):
            d = e.data
            packet = type(d) is RfPacket
            data = d.data if packet else d
            end += len(data)
            payloads.append(data)
            rows.append((e.t_ns, rank[e.port], packet, d.src64 if packet else 0,
                         d.src16 if packet else 0, d.options if packet else 0, end))
            if e.marks:
                marks[i] = [{**m, "fault": number[id(m["fault"])]} for m in e.marks]
        if rows:
            fields[:] = rows
        air_fields = np.zeros(len(air), _AIR)
        if air:
            air_fields["t"] = [a.t_ns for a in air]
            air_fields["end"] = np.cumsum([len(a.psdu) for a in air])
        head = {"from": lo, "to": hi, "events": len(events), "air": len(air), "marks": marks,
                "dropped": {p: c.dropped for p, c in channels.items()}}
        f.write(json.dumps(head).encode() + b"\n")
        f.write(fields.tobytes())
        f.write(air_fields.tobytes())
        f.write(b"".join(payloads))
        f.write(b"".join(a.psdu for a in air))

    @staticmethod
    def parse(data: bytes) -> tuple[dict, _Events, _Air]:
        cut = data.index(b"\n") + 1
        head = json.loads(data[:cut])
        n, m = head["events"], head["air"]
        fields = np.frombuffer(data, _EVENT, n, cut)
        at = cut + fields.nbytes
        air = np.frombuffer(data, _AIR, m, at)
        at += air.nbytes
        size = int(fields["end"][-1]) if n else 0
        blob = data[at:at + size]
        marks = {int(k): v for k, v in head["marks"].items()}
        return head, _Events(fields, blob, marks), _Air(air, data[at + size:])


def _child(world, parent: int, sock: socket.socket) -> int:
    """The maker: make and send blocks, one beyond what the parent has taken; serve its
    commands; end at their end. Returns the exit status."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if not die_with_parent(parent, signal.SIGKILL):
        return 0
    keep = sock.fileno()
    os.closerange(3, keep)
    os.closerange(keep + 1, os.sysconf("SC_OPEN_MAX"))
    number = {id(f): n for n, f in enumerate(world.scenario.faults)}
    live: dict[int, object] = {}
    returned = sent = world._returned_ns
    held, k, failed = False, 0, False
    end = world.duration_ns
    while True:
        making = not held and not failed and sent < end and (
            world._generated_ns > sent or world._generated_ns < returned + world.BLOCK_NS)
        if not making or select.select([sock], [], [], 0)[0]:
            command = sock.recv(65536)
            if not command:
                return 0
            what, value = _NOTE.unpack_from(command)
            if what == MORE:
                returned = max(returned, value)
            elif what == HOLD:
                held = True
                sock.send(_NOTE.pack(HELD, world._generated_ns))
            elif what == RELEASE:
                held = False
            elif what == INJECT:
                spec = json.loads(command[_NOTE.size:])
                fault = build(Fault, spec["fault"], (("fault", 0),))
                world.inject(fault)
                number[id(fault)] = spec["n"]
                live[spec["n"]] = fault
            elif what == REMOVE:
                world.remove(live.pop(value))
            continue
        target = world._generated_ns if world._generated_ns > sent else min(
            world._generated_ns + world.BLOCK_NS, end)
        fd = os.memfd_create(f"navtwin-block-{k}", os.MFD_CLOEXEC)
        with open(fd, "wb") as f:
            try:
                events = world.advance(target)
                _Block.write(f, sent, target, events, world.air(target), world._rank, number,
                             world.channels)
                what = BLOCK
            except BaseException:  # the parent raises it where it asks for the events
                f.seek(0)
                f.truncate()
                f.write(traceback.format_exc().encode())
                what, failed = FAILED, True
            f.flush()
            socket.send_fds(sock, [_NOTE.pack(what, k)], [f.fileno()])
        sent, k = target, k + 1
