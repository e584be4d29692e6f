"""``kind = "garbage"``: bursts of random bytes on the line, ``rate_hz`` bursts a second.

Peers: pymodbus's simulator ``junk`` (n bytes instead of a response), a noisy idle RS-232
line. Bursts come as a Poisson process in episode time; a burst goes on the line at its
time if the line is idle, else as soon as the chunk in progress has ended (never inside a
chunk), as its own chunk. Its length is uniform in [min_bytes, max_bytes]. One ledger
entry per burst (its range).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from navtwin.common.schema import Invalid, between, key

from .base import LineFault
from .line import FaultWrapper

MAX_BURST = 4096


@dataclass(frozen=True, kw_only=True)
class Garbage(LineFault):
    """Bursts of garbage: random bytes at a rate, between the chunks."""
    KIND = "garbage"
    # from one a fortnight: a mean gap of 1e9 / rate_hz ns stays a finite float
    rate_hz: float = key(1.0, "1/s", "bursts per second of episode (a Poisson process)",
                         between(1e-6, 1e6))
    min_bytes: int = key(1, "B", "shortest burst", between(1, MAX_BURST))
    max_bytes: int = key(16, "B", "longest burst", between(1, MAX_BURST))

    def __post_init__(self):
        super().__post_init__()
        if self.max_bytes < self.min_bytes:
            raise Invalid("max_bytes", f"must be at least min_bytes ({self.max_bytes} < "
                                       f"{self.min_bytes}); raise max_bytes or lower min_bytes")

    def wrapper(self, rng):
        return _Garbage(self, rng)


class _Garbage(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.elapsed = 0.0  # episode time (ns) of the next burst
        self.next_ns = self._draw()

    def _draw(self) -> int | None:
        self.elapsed += math.ceil(self.rng.exponential(1e9 / self.fault.rate_hz))
        return self.fault.at_active(self.elapsed)

    def send(self, start_ns, data, baud):
        return start_ns, data  # bursts come between the chunks, through release

    def due_ns(self):
        return self.next_ns

    def release(self, t_ns, baud):
        n = int(self.rng.integers(self.fault.min_bytes, self.fault.max_bytes + 1))
        burst = self.rng.integers(0, 256, n, dtype="u1").tobytes()
        self.mark(t_ns, 0, n, due_ns=self.next_ns)
        self.next_ns = self._draw()
        return t_ns, burst
