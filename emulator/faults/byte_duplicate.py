"""``kind = "byte_duplicate"``: bytes received twice, each with probability ``probability``.

One ledger entry per duplicate: its range is the extra copy (the byte after the original).
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, positive

from .base import LineFault
from .byte_drop import PER_BYTE
from .line import FaultWrapper, Gaps, insert


@dataclass(frozen=True, kw_only=True)
class ByteDuplicate(LineFault):
    """Duplicated bytes: each byte arrives twice with the given probability."""
    KIND = "byte_duplicate"
    probability: float = key(1e-3, "", PER_BYTE, positive(hi=1.0))

    def wrapper(self, rng):
        return _ByteDuplicate(self, rng)


class _ByteDuplicate(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.gaps = Gaps(rng, fault.probability)

    def act(self, start_ns, data, baud):
        out, added = insert(data, self.gaps.take(len(data)), data.__getitem__, after=True)
        for at, _ in added:
            self.mark(start_ns, at, at + 1)
        return start_ns, out
