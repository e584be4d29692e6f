"""``kind = "anchor_outage"``: the anchor is silent, its exchanges time out (status 0x40)."""
from __future__ import annotations

from dataclasses import dataclass


from .base import AnchorFault


@dataclass(frozen=True, kw_only=True)
class AnchorOutage(AnchorFault):
    """The anchor is silent: its exchanges time out (status 0x40 reports)."""
    KIND = "anchor_outage"

    def act(self, effect, on) -> None:
        effect.timeout |= on
