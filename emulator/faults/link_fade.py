"""``kind = "link_fade"``: the XBee RF link fades, most attempts are lost."""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import between, key

from .base import DeviceFault


@dataclass(frozen=True, kw_only=True)
class LinkFade(DeviceFault):
    """The RF link fades (a body in the path, a door closing): each attempt in the window is
    lost with probability ``attempt_loss`` instead of the link's own, so packets get through
    after retries, late, or not at all; the host's transmit requests get 0x8B failures."""
    KIND = "link_fade"
    ACTS_ON = "link"
    attempt_loss: float = key(0.7, "", "probability that one RF attempt is lost", between(0, 1))

    def act(self, effect, on) -> None:
        effect.lost[on] = effect.u[on] < self.attempt_loss
