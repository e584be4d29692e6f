"""``kind = "bit_errors"``: noise on the line, each bit flipped with probability ``ber``.

Peers: com0com's ``EmuNoise`` (a probability per byte), toxiproxy's requested ``corrupt``
toxic (PR #451). Bits are numbered as the UART sends them (bit 0, the LSB, first); one
ledger entry per corrupted byte, with the ``mask`` of the bits flipped.
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, positive

from .base import LineFault
from .line import FaultWrapper, Gaps


@dataclass(frozen=True, kw_only=True)
class BitErrors(LineFault):
    """Bit errors at a bit error rate: each data bit flips with probability ber."""
    KIND = "bit_errors"
    ber: float = key(1e-4, "", "bit error rate: the probability that a bit flips",
                     positive(hi=1.0))

    def wrapper(self, rng):
        return _BitErrors(self, rng)


class _BitErrors(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.gaps = Gaps(rng, fault.ber)

    def act(self, start_ns, data, baud):
        flips = self.gaps.take(8 * len(data))
        if not flips:
            return start_ns, data
        out = bytearray(data)
        masks: dict[int, int] = {}
        for bit in flips:
            masks[bit >> 3] = masks.get(bit >> 3, 0) | 1 << (bit & 7)
        for i, mask in masks.items():
            out[i] ^= mask
            self.mark(start_ns, i, i + 1, mask=mask)
        return start_ns, bytes(out)
