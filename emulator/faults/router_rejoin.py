"""``kind = "router_rejoin"``: a vehicle's XBee router leaves the network and joins again."""
from __future__ import annotations

from dataclasses import dataclass

from .base import RouterFault


@dataclass(frozen=True, kw_only=True)
class RouterRejoin(RouterFault):
    """The router is out of the network from start_s to end_s (a reset, a network leave):
    nothing it sends arrives; then it joins again under a new 16-bit address (MY, drawn
    from the vehicle's stream), which the coordinator learns from its next packet. The
    64-bit address, by which a host should know it, stays."""
    KIND = "router_rejoin"

    def act(self, effect, on) -> None:
        effect.absent |= on
