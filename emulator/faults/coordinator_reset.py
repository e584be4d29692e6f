"""``kind = "coordinator_reset"``: the lab computer's XBee coordinator loses power."""
from __future__ import annotations

from dataclasses import dataclass

from .base import CoordinatorFault


@dataclass(frozen=True, kw_only=True)
class CoordinatorReset(CoordinatorFault):
    """The coordinator is off from start_s to end_s: RF packets are not reported, host frames
    are not answered; at end_s it powers up as at the start of a run (modem status 0x00, then
    0x06), with the registers it had saved (WR), so a value set but not written is lost."""
    KIND = "coordinator_reset"

    def act(self, effect, on) -> None:
        effect.off |= on
