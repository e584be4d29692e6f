"""``kind = "latency"``: each chunk arrives ``delay_s`` (+- ``jitter_s``) after it was ready.

Peers: toxiproxy's ``latency`` (latency and jitter), ArduPilot's ``SIM_GPS_LAG_MS``, a
USB-serial adapter's latency timer. The delay counts from the chunk's ready time (when
the line would have started it), so a steady stream keeps its rate and is only shifted; it
holds the line: chunks stay in order and never overlap, so one drawn shorter than the one
before waits behind it. The jitter is uniform in [-jitter_s, +jitter_s] (the delay never
below 0). One ledger entry per chunk held, with ``delay_ns`` (its start after its ready
time) and ``held_ns`` (how much later it started than it would have without this fault's
hold on it).
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, non_negative

from .base import LineFault
from .line import FaultWrapper

MAX_DELAY_S = 3600.0


@dataclass(frozen=True, kw_only=True)
class Latency(LineFault):
    """Added latency with jitter; chunks stay in order."""
    KIND = "latency"
    CHANGES_BYTES = False  # the bytes arrive intact, later
    delay_s: float = key(0.05, "s", "added delay", non_negative(hi=MAX_DELAY_S))
    jitter_s: float = key(0.0, "s", "the delay varies uniformly by up to this either way",
                          non_negative(hi=MAX_DELAY_S))

    def wrapper(self, rng):
        return _Latency(self, rng)


class _Latency(FaultWrapper):
    def act(self, start_ns, data, baud):
        delay = self.fault.delay_s
        if self.fault.jitter_s:
            delay += self.rng.uniform(-self.fault.jitter_s, self.fault.jitter_s)
        at = max(start_ns, self.line.ready_ns + round(max(delay, 0.0) * 1e9))
        if at > start_ns:
            self.mark(at, 0, len(data), delay_ns=at - self.line.ready_ns, held_ns=at - start_ns)
        return at, data
