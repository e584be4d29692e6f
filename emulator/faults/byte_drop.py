"""``kind = "byte_drop"``: bytes lost on the line, each with probability ``probability``.

Peers: ArduPilot's ``SIM_GPS_BYTELOSS`` (a percentage of bytes). One ledger entry per run
of adjacent lost bytes: ``start == end`` where they would have been, ``removed`` = how many.
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, positive

from .base import LineFault
from .line import FaultWrapper, Gaps, remove

PER_BYTE = "the probability that a byte is hit"


@dataclass(frozen=True, kw_only=True)
class ByteDrop(LineFault):
    """Dropped bytes: each byte is lost with the given probability."""
    KIND = "byte_drop"
    probability: float = key(1e-3, "", PER_BYTE, positive(hi=1.0))

    def wrapper(self, rng):
        return _ByteDrop(self, rng)


class _ByteDrop(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.gaps = Gaps(rng, fault.probability)

    def act(self, start_ns, data, baud):
        out, runs = remove(data, self.gaps.take(len(data)))
        for at, n in runs:
            self.mark(start_ns, at, at, removed=n)
        return start_ns, out
