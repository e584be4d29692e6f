"""A port's UART line: the public seam between a device and the bytes a client reads.

A :class:`Line` times what its device writes: a chunk of n bytes occupies
``protocols.serial.wire_ns(n, baud)`` (8N1, 10 bits a byte), chunks never overlap (a chunk
starts at the later of its ready time and the end of the previous chunk, in ready order),
and a chunk is delivered whole when its last byte would have arrived. The device's
transmit buffer may be bounded (the coordinator's ``admit``). Times are integer
nanoseconds since the run started.

A device is any object with ``.baud`` and the two calls of :class:`Wire`; one that can
render many items at once also has ``render_all`` and ``room`` (its transmit buffer's bytes,
None: unbounded; its ``admit`` drops an item exactly when what is queued and the item do
not fit), which :meth:`Line.drain` uses. Between the
device and its line sit the line's wrappers (:class:`LineWrapper`, as pyserial's ``spy://``
wraps a port): each sees every chunk the device hands the UART, with its start time and
baud, and gives back the chunk to send, changed, shortened, lengthened, emptied (dropped),
started later (a stalled line) or cut into pieces sent one after another (a list of
``(start_ns, data)``); a wrapper may also hold bytes back and send them when it asks to
(``due_ns``/``release``: a stuck line, noise on an idle line). The line times what the last
wrapper returns. An ``Emulation`` installs them with ``Emulation.wrap(port, wrapper)``; the
line-level fault kinds (emulator.faults) make theirs from the scenario.

What the host writes reaches the device through an :class:`Inbound`, which runs the same
wrappers (the ``to_device`` faults) over each read: a read of n bytes at t is taken as a
chunk that started on the wire n byte-times before t, so with no wrapper the device gets
the bytes at t, as read.

Ledger. A wrapper marks what it did with :meth:`LineWrapper.mark` (byte offsets within what
it returned for the call); the line turns them into offsets in the port's stream (the
bytes as delivered, i.e. as recorded in ``<port>.bin``) and adds them to its ledger
(emulator.ledger) once those bytes are delivered: a run that stops while they are on the
line records neither them nor their entries. With several wrappers on one line, the last
one's offsets are exact; an earlier one's are exact when the wrappers after it keep the
length of what it returned.
"""
from __future__ import annotations

import bisect
import heapq
from collections import deque
from dataclasses import dataclass
from typing import Any, Iterable, NamedTuple

import numpy as np

from navtwin.protocols.serial import wire_ns

END = 1 << 62  # later than any event


class Drained(NamedTuple):
    """A drained line's chunks (:meth:`Line.drain`): their bytes end to end, each one's
    size and start (ns)."""

    data: bytes
    sizes: list[int]
    starts: list[int]


class Irregular(ValueError):
    """A line the quick path (:meth:`Line.drain`) does not time: the reason."""


class Marked(NamedTuple):
    """A device's item (bytes, or what its ``render`` takes) with ledger marks: a device
    fault changed it. Each mark is ``{"kind", "fault" (the Fault), "t_ns", **detail}``; the
    line writes one ledger entry per mark over the bytes the item became."""

    item: Any
    marks: tuple


@dataclass(slots=True)
class Chunk:
    port: str
    start_ns: int  # first byte leaves the device's UART
    end_ns: int  # last byte has arrived; the chunk is delivered now
    data: bytes
    baud: int  # the device's rate when the chunk started (the XBee's BD may change it)


class Wire:
    """A device that writes its bytes as they are (SINS board, nanoLOC gateway)."""

    room = None  # it never drops what it writes

    def __init__(self, baud: int) -> None:
        self.baud = baud

    @staticmethod
    def admit(t_ns: int, item: bytes, queued: int) -> int:
        return len(item)  # the board and the gateway never drop what they write

    @staticmethod
    def render(t_ns: int, item: bytes) -> bytes:
        return item

    @staticmethod
    def render_all(ready, items: list[bytes]) -> tuple[bytes, list[int]]:
        return b"".join(items), list(map(len, items))


class LineWrapper:
    """A filter between a device and its line; the base passes every chunk through.

    :meth:`send` is called once per chunk (or piece of the wrapper before it), in line
    order, when the chunk would start; it returns ``(start_ns, data)``: the same for no
    change, other bytes to change, drop or add bytes (the line times them: more bytes take
    longer), ``b""`` to drop the chunk, or a later ``start_ns`` (never earlier) to hold the
    line idle until then; or a list of such pairs, the pieces of the chunk, sent in order,
    each when the line is free and not before its start. A wrapper that holds bytes back
    names the time it wants to send them in :meth:`due_ns`; the line calls :meth:`release`
    then (or when it is next free) and sends what it returns, ahead of the next chunk.

    While a chunk is handled, ``self.line.ready_ns`` is when it was ready (its start had
    the line been free). A wrapper that draws random numbers takes its own stream
    (emulator.rng), so the other ports' bytes do not change. ``kind``, ``fault_index`` and
    ``direction`` name it in the ledger.
    """

    kind = ""
    fault_index: int | None = None  # its place in the scenario's [[faults]]
    direction = "to_host"

    def attach(self, line) -> None:
        """Called when installed on *line* (a :class:`Line` or :class:`Inbound`)."""
        self.line = line
        self.marks: list[dict] = []

    def send(self, start_ns: int, data: bytes, baud: int):
        return start_ns, data

    def due_ns(self) -> int | None:
        """When the wrapper has bytes of its own to send (None: never)."""
        return None

    def release(self, t_ns: int, baud: int):
        """What to send at *t_ns* (>= :meth:`due_ns`), as :meth:`send` returns it."""
        return []

    def mark(self, t_ns: int, start: int, end: int, **detail) -> None:
        """Record one injection for the ledger: bytes ``[start, end)`` of what this call
        returns (all its pieces together; ``start == end`` where bytes were removed)."""
        self.marks.append({"t_ns": int(t_ns), "start": int(start), "end": int(end), **detail})


def _pieces(wrapper, result, start_ns: int, port: str) -> list:
    """A wrapper's result as a list of non-empty (start_ns, data), refusing early starts."""
    pieces = result if isinstance(result, list) else [result]
    for s, _ in pieces:
        if s < start_ns:
            raise ValueError(f"{type(wrapper).__name__} moved a {port} chunk earlier "
                             f"({s} < {start_ns} ns); a line cannot send early")
    return [(s, bytes(d)) for s, d in pieces if d]


class _Wrapped:
    """The wrappers of one direction of a port, and the ledger their marks go to."""

    def __init__(self, name: str, wrappers: Iterable[LineWrapper], ledger) -> None:
        self.name = name
        self.ledger = ledger
        self.wrappers: list[LineWrapper] = []
        self.ready_ns = 0
        self.bytes = 0  # bytes of the stream so far: the offset of the next one
        for w in wrappers:
            self.wrap(w)

    def wrap(self, wrapper: LineWrapper) -> None:
        """Put *wrapper* after the wrappers already there."""
        wrapper.attach(self)
        self.wrappers.append(wrapper)

    def _due(self) -> tuple[int, int]:
        """(time, index) of the earliest wrapper release; (END, -1) if none."""
        best = (END, -1)
        for k, w in enumerate(self.wrappers):
            t = w.due_ns()
            if t is not None and t < best[0]:
                best = (t, k)
        return best

    def _chain(self, k: int, t: int, ready: int, data: bytes | None, baud: int) -> list:
        """The pieces wrappers[k:] make of a chunk (*data* None: wrapper k's release)."""
        self.ready_ns = ready
        if data is None:
            w = self.wrappers[k]
            pieces = _pieces(w, w.release(t, baud), t, self.name)
            k += 1
        else:
            pieces = [(t, data)]
        for w in self.wrappers[k:]:
            out, done = [], 0
            for s, d in pieces:
                n = len(w.marks)
                got = _pieces(w, w.send(s, d, baud), s, self.name)
                for m in w.marks[n:]:  # offsets of this call -> of all this wrapper returned
                    m["start"] += done
                    m["end"] += done
                done += sum(len(x) for _, x in got)
                out += got
            pieces = out
        return pieces

    def _settle(self, size: int | None) -> None:
        """The wrappers' marks into the ledger at the stream's current offset, cut to the
        *size* bytes that go into the stream (None: none of it goes, the marks are void)."""
        for w in self.wrappers:
            if w.marks and size is not None and self.ledger is not None:
                for m in w.marks:
                    self._enter({"kind": w.kind, "fault": w.fault_index, "port": self.name,
                                 "direction": w.direction, **m,
                                 "start": self.bytes + min(m["start"], size),
                                 "end": self.bytes + min(m["end"], size)})
            w.marks.clear()

    def _enter(self, entry: dict) -> None:
        """Add a ledger entry of this stream."""
        self.ledger.add(**entry)


class Line(_Wrapped):
    """One port's UART: items in ready order, taken into the device's transmit buffer when
    ready, sent one chunk at a time.

    ``queued`` = bytes in the buffer: items waiting plus the chunk in progress (counted
    whole until its last byte has arrived; a chunk cut in pieces, each piece until its own
    last byte has). At its ready time an item goes to ``device.admit(ready, item, queued)``,
    which gives its size or None to drop it (the coordinator's bounded buffer); every step
    is taken in time order, so what is dropped depends on the timeline only, not on when
    the loop polls.

    So the loop need not wake when a chunk starts, only when one ends: on an idle line
    without wrappers, :meth:`next_ns` is the end of the chunk the next item will be, where
    the device can say now how many bytes it will render then (``device.size(t, item)``,
    None: it cannot), and the poll at that end takes the item's arrival, its start and its
    end in order. The coordinator can (its RF packets come at their own instants per car,
    and woke the loop twice each); a :class:`Wire` does not say, on purpose: the cars' SINS
    frames and reports start together, so their starts cost one wake-up for all of them,
    and taken there they stay out of the burst of their ends (taken at the ends, they made
    a burst of 50 cars 1 ms late 3-10 times as often: ``navtwin bench emulator-writes``).
    What changes a line or its device from outside the timeline (the host's bytes at the
    device, a live fault) comes after :meth:`catch_up` to its time, so it finds the line as
    a poll at every step would have left it.
    """

    def __init__(self, name: str, device: Any, wrappers: Iterable[LineWrapper] = (),
                 ledger=None) -> None:
        # .baud, .admit(t_ns, item, queued), .render(t_ns, item), and optionally .size(t_ns,
        # item), .render_all(ready, items) with .room (the module doc)
        self.device = device
        self._pending: list = []  # heap of (ready, seq, item) not yet in the buffer
        self._queue: deque = deque()  # (ready, item, size) in the buffer, in ready order
        self._pieces: deque = deque()  # (start, data, baud) of the chunk being sent, not started
        self._seq = 0
        self.queued = 0
        self.free_ns = 0
        self.current: Chunk | None = None
        self.chunks = 0
        self.delivered = 0  # bytes of the chunks delivered: the stream as recorded so far
        self._held: list[dict] = []  # ledger entries naming bytes not delivered yet
        self._ended: list[Chunk] = []  # ended in a catch_up, for the next poll to give
        self._size = getattr(device, "size", None)  # a device without it: no look-ahead
        # device -> wrappers[0] -> ... -> wrappers[-1] -> line; .bytes: bytes sent so far
        super().__init__(name, wrappers, ledger)

    def put(self, t_ns: int, item: Any) -> None:
        heapq.heappush(self._pending, (t_ns, self._seq, item))
        self._seq += 1

    def put_many(self, t_ns: list[int], items: list) -> None:
        """:meth:`put` of each item at its time, in order. The pending items are kept sorted,
        which is a heap too, so :meth:`drain` finds them in order (a port's events come
        nearly so: the sort is close to one pass)."""
        self._pending += zip(t_ns, range(self._seq, self._seq + len(items)), items)
        self._seq += len(items)
        self._pending.sort()

    def _next_start(self, end_ns: int) -> tuple[int, int]:
        """(time, what) of the next chunk start on an idle line: what = -2 the next piece,
        -1 the next item of the buffer, k >= 0 wrapper k's release; (END, 0) if none
        before *end_ns*. A release due by an item's start goes first."""
        if self._pieces:  # all start before the end of the run (see _launch)
            return max(self._pieces[0][0], self.free_ns), -2
        start, what = END, 0
        if self._queue:
            start, what = max(self._queue[0][0], self.free_ns), -1
        if self.wrappers:
            due, k = self._due()
            if due < END and max(due, self.free_ns) <= start:
                start, what = max(due, self.free_ns), k
        return (start, what) if start < end_ns else (END, 0)

    def next_ns(self) -> int | None:
        """When this line next has something to do: end of the chunk in progress, or on an
        idle line the start of the next chunk: a piece, the buffer's next item, a wrapper's
        release, or an item arriving, whichever comes first (a wrapper due later must not
        hide an item due now: the loop polls a line only at this time, emulator.schedule).
        An item that arrives while a chunk is on the wire waits for its end."""
        if self._ended:
            return self._ended[0].end_ns
        if self.current is not None:
            return self.current.end_ns
        start, _ = self._next_start(END)
        if self._pending:
            arrive = max(self._pending[0][0], self.free_ns)
            if arrive < start:
                start = self._end_of(arrive) if start == END and not self.wrappers else arrive
        return start if start < END else None

    def _end_of(self, t: int) -> int:
        """When the chunk of the next item, arriving at *t* on an idle line with nothing
        else to send, ends (*t* itself when the device cannot tell its size now)."""
        item = self._pending[0][2]
        size = None if self._size is None or type(item) is Marked else self._size(t, item)
        return t + wire_ns(size, self.device.baud) if size else t

    def catch_up(self, now_ns: int, known_ns: int, end_ns: int) -> None:
        """Take every step due by *now_ns* now; the chunks that ended wait for the next
        :meth:`poll`. Call it before a change from outside the timeline at *now_ns*."""
        self._ended = self.poll(now_ns, known_ns, end_ns)  # those it kept before, then these

    def poll(self, now_ns: int, known_ns: int, end_ns: int) -> list[Chunk]:
        """Chunks that have ended by *now_ns*; starts those due. An item enters the buffer
        only when all items that could precede it are known (ready < *known_ns*), and
        starts before *end_ns*."""
        out, self._ended = self._ended, []
        pending, queue = self._pending, self._queue
        limit = min(known_ns, end_ns)
        while True:
            # the earliest step; on a tie a chunk ends before an item arrives, and an item
            # arrives before the next chunk starts
            cur = self.current
            t = pending[0][0] if pending and pending[0][0] < limit else END  # next arrival
            if cur is not None:
                arrive = t < cur.end_ns
                if not arrive:
                    t = cur.end_ns
            else:
                start, what = self._next_start(end_ns)
                arrive = t <= start
                if not arrive:
                    t = start
            if t == END or t > now_ns:
                return out
            if arrive:
                ready, _, item = heapq.heappop(pending)
                size = self.device.admit(ready, item.item if type(item) is Marked else item,
                                         self.queued)
                if size is not None:
                    queue.append((ready, item, size))
                    self.queued += size
            elif cur is not None:
                out.append(cur)
                self.current = None
                self.queued -= len(cur.data)
                self.delivered += len(cur.data)
                if self._held:
                    self._release()
            elif what == -2:
                _, data, baud = self._pieces.popleft()
                self._start(t, data, baud)
            else:
                baud = self.device.baud  # before rendering: a BD change applies to later chunks
                marks = ()
                offset = self.bytes + (sum(len(d) for _, d, _ in self._pieces) if self._pieces else 0)
                if what == -1:
                    ready, item, size = queue.popleft()
                    self.queued -= size
                    if type(item) is Marked:
                        item, marks = item
                    data = self.device.render(ready, item)
                    if not self.wrappers:
                        # its one piece starts now (t < end_ns, the line is free and no
                        # arrival is due by t): the step a queued piece would take next
                        sent = len(data)
                        if data:
                            self.queued += sent
                            self._start(t, data, baud)
                        pieces = None
                    else:
                        pieces = self._chain(0, t, ready, data, baud) if data else []
                else:
                    pieces = self._chain(what, t, t, None, baud)
                if pieces is not None:
                    sent = self._launch(pieces, baud, end_ns)
                if marks and sent and self.ledger is not None:
                    for m in marks:
                        self._enter({**m, "fault": self.ledger.index(m["fault"]),
                                     "port": self.name, "direction": "to_host",
                                     "start": offset, "end": offset + sent})

    def drain(self, end_ns: int) -> Drained:
        """Every chunk of the items put, as :meth:`poll` sends them over a run that ends at
        *end_ns* with nothing else happening on the line (no host write, no live fault, no
        later put). The quick path of an in-memory run (Emulation.chunks): the chunks
        timed in ready order, not by the timeline's steps.

        In ready order, an item is admitted with ``queued`` = the bytes of the items
        admitted before it whose chunks have not ended (a chunk ending at its arrival has
        ended, as in poll), and its chunk starts at the later of its ready time and the
        previous chunk's end, if that is before *end_ns*; the items after one that does not
        start wait behind it (admitted all the same, so the device counts what it drops).
        The device renders an item right after admitting it, where poll renders it at its
        start, after the admissions up to then: the same bytes for a device whose rendering
        of an item does not depend on what it admitted meanwhile (the SINS board's and the
        gateway's wires; the coordinator's RF packets, each frame a function of the packet
        and the modes). :class:`Irregular` (the line is then spent) for a line that has
        sent anything or has wrappers, an item with ledger marks, or a rendering whose
        length is not what was admitted (a reply that reconfigures the radio, a packet
        dropped at its start).

        A device that renders its items all at once (``render_all``) has them timed in a
        few numpy calls (:meth:`_timed`), where none would be dropped; the others, and a
        buffer that overflows, item by item (:meth:`_each`): the same chunks."""
        if self.wrappers or self.chunks or self.current is not None or self._queue:
            raise Irregular(f"{self.name}: a line with wrappers or history")
        self._pending.sort()  # a heap (put) or in order already (put_many)
        items, self._pending = self._pending, []
        items = items[:bisect.bisect_left(items, (end_ns,))]  # ready before the end
        if any(type(item) is Marked for _, _, item in items):
            raise Irregular(f"{self.name}: an item with ledger marks")
        render_all = getattr(self.device, "render_all", None)
        got = None
        if render_all is not None and items:
            ready = np.fromiter((r for r, _, _ in items), np.int64, len(items))
            rendered = render_all(ready, [item for _, _, item in items])
            if rendered is not None:
                got = self._timed(ready, *rendered, end_ns)
        if got is None:
            got = self._each(items, end_ns)
        self.chunks = len(got.sizes)
        self.bytes = self.delivered = len(got.data)
        return got

    def _timed(self, ready: np.ndarray, data: bytes, sizes: np.ndarray, end_ns: int) -> Drained | None:
        """The chunks of items ready at *ready*, rendered to *data* (*sizes* bytes each),
        all admitted: chunk i ends at e_i = max(r_i, e_{i-1}) + d_i from e_-1 = the line's
        free time, i.e. e_i = D_i + max(free, max_{k<=i} (r_k - D_{k-1})) with D the
        running sum of the durations d, a running maximum (integers: exact). An item of no
        bytes makes no chunk and leaves the line as it was. None when the device's buffer
        (``room``) would have dropped one, which only the item-by-item pass counts."""
        sizes = np.asarray(sizes, dtype=np.int64)
        some = sizes > 0
        r, n = ready[some], sizes[some]
        d = wire_ns(n, self.device.baud)
        total = np.cumsum(d)
        ends = total + np.maximum.accumulate(np.maximum(r - (total - d), self.free_ns))
        starts = ends - d
        sent = int(np.searchsorted(starts, end_ns))  # starts rise: those before the end
        room = getattr(self.device, "room", None)
        if room is not None:  # what each item finds queued: admitted before it, not ended
            ended = np.concatenate(([0], np.cumsum(n[:sent])))[
                np.searchsorted(ends[:sent], ready, side="right")]
            if np.any(np.cumsum(sizes) - ended > room):  # queued + its own size
                return None
        cut = int(n[:sent].sum())
        return Drained(data[:cut], n[:sent].tolist(), starts[:sent].tolist())

    def _each(self, items: list, end_ns: int) -> Drained:
        """:meth:`drain`'s chunks, item by item (*items*: (ready, seq, item), in order)."""
        admit, render = self.device.admit, self.device.render
        datas: list[bytes] = []
        starts: list[int] = []
        ends: list[int] = []  # of the chunks started, increasing
        free, admitted, ended, done = self.free_ns, 0, 0, 0  # done: chunks ended so far
        stopped = False
        for ready, _, item in items:
            while done < len(ends) and ends[done] <= ready:
                ended += len(datas[done])
                done += 1
            size = admit(ready, item, admitted - ended)
            if size is None:
                continue
            admitted += size
            start = ready if ready > free else free
            if stopped or start >= end_ns:
                stopped = True  # it waits past the end, and every later item behind it
                continue
            data = render(ready, item)
            if len(data) != size:
                raise Irregular(f"{self.name}: rendered {len(data)} bytes of {size} admitted")
            if not data:
                continue  # nothing to send: no chunk, as in poll
            free = start + wire_ns(size, self.device.baud)
            datas.append(data)
            starts.append(start)
            ends.append(free)
        return Drained(b"".join(datas), list(map(len, datas)), starts)

    def _start(self, t: int, data: bytes, baud: int) -> None:
        """Put *data* on the wire from *t*: the chunk in progress."""
        end = t + wire_ns(len(data), baud)
        self.current = Chunk(self.name, t, end, data, baud)
        self.free_ns = end
        self.chunks += 1
        self.bytes += len(data)

    def _launch(self, pieces: list, baud: int, end_ns: int) -> int:
        """Queue the pieces of a chunk that will start before *end_ns* (each starts when
        the line is free, not before its own start); the wrappers' marks go to the ledger,
        cut to the bytes that are sent, unless none are (a chunk held past the end)."""
        free, sent = self.free_ns, 0
        for s, d in pieces:
            s = max(s, free)
            if s >= end_ns:
                break
            free = s + wire_ns(len(d), baud)
            self._pieces.append((s, d, baud))
            self.queued += len(d)
            sent += len(d)
        if self.wrappers:
            self._settle(sent if sent or not pieces else None)
        return sent

    def _enter(self, entry: dict) -> None:
        """Add *entry* once the bytes it names are delivered: a run that stops while they
        are on the line has neither them nor the entry in its recording."""
        if entry["end"] <= self.delivered:
            self.ledger.add(**entry)
        else:
            self._held.append(entry)

    def _release(self) -> None:
        """Add the held entries whose bytes are now delivered, in the order they came."""
        held, self._held = self._held, []
        for entry in held:
            self._enter(entry)

    def busy(self, end_ns: int) -> bool:
        """Whether the line still has work: a chunk on the wire or ended and not given, or
        an item that starts before *end_ns* (its deadline may be its end, after it)."""
        return (self.current is not None or bool(self._pieces) or bool(self._ended)
                or bool(self._pending) and max(self._pending[0][0], self.free_ns) < end_ns)


class Inbound(_Wrapped):
    """What the host writes to a port on its way to the device, through the port's
    ``to_device`` wrappers. :meth:`put` a read; :meth:`poll` gives ``(t_ns, data)`` when
    the device gets it: the end of each piece's time on the wire, in order."""

    def __init__(self, name: str, device: Any, wrappers: Iterable[LineWrapper] = (),
                 ledger=None) -> None:
        self.device = device  # .baud
        self._out: deque = deque()  # (t_ns, data) not yet given to the device
        self._last = -END
        super().__init__(name, wrappers, ledger)

    def put(self, t_ns: int, data: bytes) -> None:
        """Bytes the host wrote, read at *t_ns*."""
        baud = self.device.baud
        start = t_ns - wire_ns(len(data), baud)  # its first byte was on the wire then
        self._emit(self._chain(0, start, start, data, baud) if self.wrappers else [(start, data)],
                   baud)

    def _emit(self, pieces: list, baud: int) -> None:
        if self.wrappers:
            self._settle(sum(len(d) for _, d in pieces))
        for s, d in pieces:
            self._last = max(s + wire_ns(len(d), baud), self._last)
            self._out.append((self._last, d))
            self.bytes += len(d)

    def next_ns(self) -> int | None:
        t = min(self._out[0][0] if self._out else END, self._due()[0] if self.wrappers else END)
        return None if t == END else t

    def poll(self, now_ns: int) -> list[tuple[int, bytes]]:
        """What the device gets by *now_ns*, in order (releases due by then included)."""
        while self.wrappers:
            due, k = self._due()
            if due > now_ns:
                break
            baud = self.device.baud
            self._emit(self._chain(k, due, due, None, baud), baud)
        out = []
        while self._out and self._out[0][0] <= now_ns:
            out.append(self._out.popleft())
        return out
