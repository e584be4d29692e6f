"""``kind = "nlos"``: non-line-of-sight to an anchor, a positive range bias and a weaker signal."""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, non_negative

from .base import AnchorFault


@dataclass(frozen=True, kw_only=True)
class Nlos(AnchorFault):
    """Non-line-of-sight: a positive range bias (exponential) and a weaker signal."""
    KIND = "nlos"
    bias_m: float = key(0.8, "m", "mean of the exponential NLOS range bias",
                        non_negative(hi=100))
    attenuation_db: float = key(6.0, "dB", "extra path loss on the RSSI", non_negative(hi=200))

    def act(self, effect, on) -> None:
        effect.bias_m[on] += self.bias_m * effect.exponential[on]
        effect.attenuation_db[on] += self.attenuation_db
