"""``kind = "stuck"``: the line is stuck for the episode; the receiver's buffer overruns.

Peers: com0com's ``EmuOverrun``, toxiproxy's ``timeout`` (stop all data). What the device
sends keeps leaving its UART at the usual times, but nothing is delivered during the
episode: the first ``buffer_bytes`` of it wait in the receiving UART's buffer (16, a
16550's FIFO, by default; 0: all is lost) and the rest is lost (an overrun: bytes that find
the buffer full are discarded, so the oldest are kept). When the episode ends the buffer
is delivered at once, as one chunk, ahead of anything else. A chunk that started before the
episode is delivered whole. One ledger entry per episode with traffic: the held bytes'
range, ``removed`` (lost to the overrun) and ``held_ns`` (from the first held chunk).
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import between, key

from .base import LineFault
from .line import FaultWrapper

MAX_BUFFER = 1 << 24


@dataclass(frozen=True, kw_only=True)
class Stuck(LineFault):
    """A stuck line: nothing arrives during the episode; the receive buffer overruns."""
    KIND = "stuck"
    buffer_bytes: int = key(16, "B", "the receiver's buffer: kept during the episode, then "
                            "delivered", between(0, MAX_BUFFER))

    def wrapper(self, rng):
        return _Stuck(self, rng)


class _Stuck(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.held = bytearray()
        self.lost = 0
        self.until_ns: int | None = None  # end of the episode with bytes held
        self.since_ns = 0

    def act(self, start_ns, data, baud):
        if self.until_ns is None:
            self.until_ns, self.since_ns = self.fault.episode_end(start_ns), start_ns
        room = self.fault.buffer_bytes - len(self.held)
        self.held += data[:room]
        self.lost += max(len(data) - room, 0)
        return start_ns, b""

    def due_ns(self):
        return self.until_ns

    def release(self, t_ns, baud):
        held = bytes(self.held)
        self.mark(t_ns, 0, len(held), removed=self.lost, held_ns=t_ns - self.since_ns)
        self.held.clear()
        self.lost, self.until_ns = 0, None
        return t_ns, held
