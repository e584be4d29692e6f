"""``kind = "range_value_error"``: the gateway reports exchanges with status 0x80."""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import between, key

from .base import AnchorFault


@dataclass(frozen=True, kw_only=True)
class RangeValueError(AnchorFault):
    """The gateway flags an anchor's exchanges as value errors (status 0x80: a timestamp out
    of range, wire-formats.md section 3), each with probability ``probability``."""
    KIND = "range_value_error"
    probability: float = key(0.5, "", "probability that one exchange is a value error",
                             between(0, 1))

    def act(self, effect, on):
        hit = on & (effect.uniform >= 1 - self.probability)
        effect.value_error |= hit
        return hit  # the exchanges it flagged
