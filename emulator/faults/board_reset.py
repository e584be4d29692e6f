"""``kind = "board_reset"``: a vehicle's SINS board loses power and boots again."""
from __future__ import annotations

from dataclasses import dataclass

from .base import BoardFault


@dataclass(frozen=True, kw_only=True)
class BoardReset(BoardFault):
    """The SINS board is off from start_s to end_s (a brown-out and its boot): it writes
    nothing, and its first frame after the episode counts from 0 again, as after power-up."""
    KIND = "board_reset"

    def act(self, effect, on) -> None:
        effect.off |= on
