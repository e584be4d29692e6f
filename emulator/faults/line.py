"""What the line fault kinds share: the wrapper of one fault, per-byte events drawn as gaps.

A line fault acts on the chunks that start inside one of its episodes (a chunk is faulted
or not as a whole, at its start time); its random numbers are drawn only for those, from
the fault's own stream, so the bytes depend on (scenario, seed) alone.
"""
from __future__ import annotations

from navtwin.emulator.uart import LineWrapper


class FaultWrapper(LineWrapper):
    """The wrapper a LineFault installs: :meth:`act` on the chunks inside an episode."""

    def __init__(self, fault, rng) -> None:
        self.fault, self.rng = fault, rng
        self.kind = fault.KIND

    def send(self, start_ns: int, data: bytes, baud: int):
        if not self.fault.active(start_ns):
            return start_ns, data
        return self.act(start_ns, data, baud)

    def act(self, start_ns: int, data: bytes, baud: int):
        """What an episode does to a chunk (as LineWrapper.send returns it)."""
        raise NotImplementedError


class Gaps:
    """Where independent events of probability *p* per unit (bit or byte) fall along a
    stream: the gap to the next one is geometric, one draw per event rather than one per
    unit; the gap carries over from one chunk to the next."""

    def __init__(self, rng, p: float) -> None:
        self.rng, self.p = rng, p
        self.skip = self._gap()  # units before the next event

    def _gap(self) -> int:
        return int(self.rng.geometric(self.p)) - 1

    def take(self, n: int) -> list[int]:
        """The positions of the events among the next *n* units."""
        out, pos = [], self.skip
        while pos < n:
            out.append(pos)
            pos += 1 + self._gap()
        self.skip = pos - n
        return out


def insert(data: bytes, positions, new_byte, after: bool = False) -> tuple[bytes, list]:
    """*data* with a byte ``new_byte(p)`` added before ``data[p]`` for each of *positions*
    (ascending; after it with *after*), and ``(offset in the result, byte)`` of each added."""
    out, added, prev = bytearray(), [], 0
    for p in positions:
        cut = p + 1 if after else p
        out += data[prev:cut]
        value = new_byte(p)
        added.append((len(out), value))
        out.append(value)
        prev = cut
    out += data[prev:]
    return bytes(out), added


def remove(data: bytes, positions) -> tuple[bytes, list[list[int]]]:
    """*data* without the bytes at *positions* (ascending), and the removals as runs
    ``[offset in the result, bytes removed]`` (adjacent removals make one run)."""
    out, runs, prev = bytearray(), [], 0
    for p in positions:
        out += data[prev:p]
        if runs and runs[-1][0] == len(out) and prev == p:
            runs[-1][1] += 1
        else:
            runs.append([len(out), 1])
        prev = p + 1
    out += data[prev:]
    return bytes(out), runs
