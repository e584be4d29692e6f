"""``kind = "link_loss"``: the XBee link is down, every RF attempt in the window is lost."""
from __future__ import annotations

from dataclasses import dataclass

from .base import DeviceFault


@dataclass(frozen=True, kw_only=True)
class LinkLoss(DeviceFault):
    """The XBee link is down: every RF packet in the window is lost."""
    KIND = "link_loss"
    ACTS_ON = "link"

    def act(self, effect, on) -> None:
        effect.lost |= on[:, None]  # every attempt of a packet whose first attempt is inside
