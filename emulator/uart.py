"""A port's UART line: the public seam between a device and the bytes a client reads.

A :class:`Line` times what its device writes: a chunk of n bytes occupies
``protocols.serial.wire_ns(n, baud)`` (8N1, 10 bits a byte), chunks never overlap (a chunk
starts at the later of its ready time and the end of the previous chunk, in ready order),
and a chunk is delivered whole when its last byte would have arrived. The device's
transmit buffer may be bounded (the coordinator's ``admit``). Times are integer
nanoseconds since the run started.

A device is any object with ``.baud`` and the two calls of :class:`Wire`. Between the
device and its line sit the line's wrappers (:class:`LineWrapper`, as pyserial's ``spy://``
wraps a port): each sees every chunk the device hands the UART, with its start time and
baud, and gives back the chunk to send, changed, shortened, lengthened, emptied (dropped)
or started later (a stalled line); the line times what the last wrapper returns. An
``Emulation`` installs them with ``Emulation.wrap(port, wrapper)``; the line-level fault
kinds (emulator.faults) make theirs from the scenario.
"""
from __future__ import annotations

import heapq
from collections import deque
from dataclasses import dataclass
from typing import Any, Iterable

from navtwin.protocols.serial import wire_ns

END = 1 << 62  # later than any event


@dataclass(slots=True)
class Chunk:
    port: str
    start_ns: int  # first byte leaves the device's UART
    end_ns: int  # last byte has arrived; the chunk is delivered now
    data: bytes
    baud: int  # the device's rate when the chunk started (the XBee's BD may change it)


class Wire:
    """A device that writes its bytes as they are (SINS board, nanoLOC gateway)."""

    def __init__(self, baud: int) -> None:
        self.baud = baud

    @staticmethod
    def admit(t_ns: int, item: bytes, queued: int) -> int:
        return len(item)  # the board and the gateway never drop what they write

    @staticmethod
    def render(t_ns: int, item: bytes) -> bytes:
        return item


class LineWrapper:
    """A filter between a device and its line; the base passes every chunk through.

    :meth:`send` is called once per chunk, in line order, when the chunk would start; it
    returns ``(start_ns, data)``: the same for no change, other bytes to change, drop or add
    bytes (the line times them: more bytes take longer), ``b""`` to drop the chunk, or a
    later ``start_ns`` (never earlier) to hold the line idle until then. A wrapper that
    draws random numbers takes its own stream (emulator.rng), so the other ports' bytes do
    not change.
    """

    def send(self, start_ns: int, data: bytes, baud: int) -> tuple[int, bytes]:
        return start_ns, data


class Line:
    """One port's UART: items in ready order, taken into the device's transmit buffer when
    ready, sent one chunk at a time.

    ``queued`` = bytes in the buffer: items waiting plus the chunk in progress (counted
    whole until its last byte has arrived). At its ready time an item goes to
    ``device.admit(ready, item, queued)``, which gives its size or None to drop it (the
    coordinator's bounded buffer); every step is taken in time order, so what is dropped
    depends on the timeline only, not on when the loop polls.
    """

    def __init__(self, name: str, device: Any, wrappers: Iterable[LineWrapper] = ()) -> None:
        self.name = name
        self.device = device  # .baud, .admit(t_ns, item, queued) and .render(t_ns, item)
        self.wrappers = list(wrappers)  # device -> wrappers[0] -> ... -> wrappers[-1] -> line
        self._pending: list = []  # heap of (ready, seq, item) not yet in the buffer
        self._queue: deque = deque()  # (ready, item, size) in the buffer, in ready order
        self._seq = 0
        self.queued = 0
        self.free_ns = 0
        self.current: Chunk | None = None
        self.chunks = 0
        self.bytes = 0

    def wrap(self, wrapper: LineWrapper) -> None:
        """Put *wrapper* between the device (and the wrappers already there) and the line."""
        self.wrappers.append(wrapper)

    def put(self, t_ns: int, item: Any) -> None:
        heapq.heappush(self._pending, (t_ns, self._seq, item))
        self._seq += 1

    def next_ns(self) -> int | None:
        """When this line next has something to do: end of the chunk in progress or start
        of the next one (an item's arrival in the buffer waits for that)."""
        if self.current is not None:
            return self.current.end_ns
        if self._queue:
            return max(self._queue[0][0], self.free_ns)
        if self._pending:
            return max(self._pending[0][0], self.free_ns)
        return None

    def poll(self, now_ns: int, known_ns: int, end_ns: int) -> list[Chunk]:
        """Chunks that have ended by *now_ns*; starts those due. An item enters the buffer
        only when all items that could precede it are known (ready < *known_ns*), and
        starts before *end_ns*."""
        out = []
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
                start = END
                if queue:
                    start = max(queue[0][0], self.free_ns)
                    if start >= end_ns:
                        start = END
                arrive = t <= start
                if not arrive:
                    t = start
            if t == END or t > now_ns:
                return out
            if arrive:
                ready, _, item = heapq.heappop(pending)
                size = self.device.admit(ready, item, self.queued)
                if size is not None:
                    queue.append((ready, item, size))
                    self.queued += size
            elif cur is not None:
                out.append(cur)
                self.current = None
                self.queued -= len(cur.data)
            else:
                ready, item, size = queue.popleft()
                self.queued -= size
                baud = self.device.baud  # before rendering: a BD change applies to later chunks
                data = self.device.render(ready, item)
                for wrapper in self.wrappers:
                    if not data:
                        break
                    start, data = wrapper.send(t, data, baud)
                    if start < t:
                        raise ValueError(f"{type(wrapper).__name__} moved a {self.name} chunk "
                                         f"earlier ({start} < {t} ns); a line cannot send early")
                    t = start
                if not data or t >= end_ns:  # dropped, or held back past the end of the run
                    continue
                end = t + wire_ns(len(data), baud)
                self.current = Chunk(self.name, t, end, data, baud)
                self.queued += len(data)
                self.free_ns = end
                self.chunks += 1
                self.bytes += len(data)

    def busy(self) -> bool:
        return self.current is not None
