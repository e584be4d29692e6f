"""``kind = "anchor_outage"``: the anchor is silent, its exchanges time out (status 0x40)."""
from __future__ import annotations

from dataclasses import dataclass

from common.limits import ANCHOR_IDS
from common.schema import REQUIRED, between, key

from .base import DeviceFault, register


@register
@dataclass(frozen=True, kw_only=True)
class AnchorOutage(DeviceFault):
    """The anchor is silent: its exchanges time out (status 0x40 reports)."""
    KIND = "anchor_outage"
    ACTS_ON = "anchor"
    anchor: int = key(REQUIRED, "", "anchor id", between(*ANCHOR_IDS))

    def act(self, effect, on) -> None:
        effect.timeout |= on
