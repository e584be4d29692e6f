"""``kind = "slicing"``: a chunk arrives in pieces of about ``piece_bytes`` with gaps.

Peers: toxiproxy's ``slicer`` (average size, size variation, delay between slices),
pymodbus's simulator ``split with delay``; a USB-serial adapter or a ser2net bridge
delivering a frame in several reads. A chunk is cut with ``probability``; each piece is
``piece_bytes`` +- ``piece_variation`` (uniform, at least 1) and starts ``gap_s`` after the
previous piece's last byte. One ledger entry per chunk cut: its range and the ``pieces``'
sizes.
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import between, key, non_negative, positive
from navtwin.protocols.serial import wire_ns

from .base import LineFault
from .line import FaultWrapper

MAX_PIECE = 1 << 16


@dataclass(frozen=True, kw_only=True)
class Slicing(LineFault):
    """Chunks delivered in pieces, with a gap between them."""
    KIND = "slicing"
    CHANGES_BYTES = False  # the bytes arrive intact, later
    probability: float = key(1.0, "", "the probability that a chunk is cut", positive(hi=1.0))
    piece_bytes: int = key(8, "B", "mean size of a piece", between(1, MAX_PIECE))
    piece_variation: int = key(0, "B", "a piece's size varies uniformly by up to this",
                               between(0, MAX_PIECE))
    gap_s: float = key(0.001, "s", "idle time between the pieces", non_negative(hi=60))

    def wrapper(self, rng):
        return _Slicing(self, rng)


class _Slicing(FaultWrapper):
    def act(self, start_ns, data, baud):
        f = self.fault
        if len(data) < 2 or (f.probability < 1 and self.rng.random() >= f.probability):
            return start_ns, data
        pieces, i, t = [], 0, start_ns
        while i < len(data):
            size = f.piece_bytes
            if f.piece_variation:
                size += int(self.rng.integers(-f.piece_variation, f.piece_variation + 1))
            piece = data[i:i + max(size, 1)]
            pieces.append((t, piece))
            i += len(piece)
            t += wire_ns(len(piece), baud) + round(f.gap_s * 1e9)
        if len(pieces) > 1:
            self.mark(start_ns, 0, len(data), pieces=[len(p) for _, p in pieces])
        return pieces
