"""``kind = "byte_insert"``: random bytes appear on the line, before each byte with
probability ``probability``.

Peers: a spurious start bit on a noisy idle line; pymodbus's simulator ``junk`` (n bytes).
One ledger entry per inserted byte (its range, and its ``value``).
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, positive

from .base import LineFault
from .byte_drop import PER_BYTE
from .line import FaultWrapper, Gaps, insert


@dataclass(frozen=True, kw_only=True)
class ByteInsert(LineFault):
    """Inserted bytes: a random byte comes before each byte with the given probability."""
    KIND = "byte_insert"
    probability: float = key(1e-3, "", PER_BYTE, positive(hi=1.0))

    def wrapper(self, rng):
        return _ByteInsert(self, rng)


class _ByteInsert(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.gaps = Gaps(rng, fault.probability)

    def act(self, start_ns, data, baud):
        out, added = insert(data, self.gaps.take(len(data)), lambda p: int(self.rng.integers(256)))
        for at, value in added:
            self.mark(start_ns, at, at + 1, value=value)
        return start_ns, out
