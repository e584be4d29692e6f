"""``kind = "bandwidth"``: the line carries at most ``bytes_per_s``, below its baud's rate.

Peers: toxiproxy's ``bandwidth`` (KB/s). A chunk of n bytes takes n / bytes_per_s on the
line (its last byte arrives then) and the next starts after it; what the device sends
faster waits in its transmit buffer (the xbee coordinator's is bounded: RF packets that
find it full are dropped). A cap above the baud's rate changes nothing. One ledger entry
per chunk held, with ``held_ns``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from navtwin.common.schema import between, key
from navtwin.protocols.serial import wire_ns

from .base import LineFault
from .line import FaultWrapper


@dataclass(frozen=True, kw_only=True)
class Bandwidth(LineFault):
    """A bandwidth cap below the line's rate."""
    KIND = "bandwidth"
    CHANGES_BYTES = False  # the bytes arrive intact, later
    # from 1 B/s: a chunk's time on the capped line, len / bytes_per_s, stays whole ns
    bytes_per_s: float = key(1000.0, "B/s", "the most the line carries", between(1, 1e7))

    def wrapper(self, rng):
        return _Bandwidth(self, rng)


class _Bandwidth(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.free_ns = 0  # when the capped line has carried what it was given

    def act(self, start_ns, data, baud):
        begin = max(start_ns, self.free_ns)
        wire = wire_ns(len(data), baud)
        self.free_ns = begin + max(math.ceil(len(data) * 1e9 / self.fault.bytes_per_s), wire)
        at = self.free_ns - wire
        if at > start_ns:
            self.mark(at, 0, len(data), held_ns=at - start_ns)
        return at, data
