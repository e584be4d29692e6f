"""``kind = "burst_loss"``: losses that come in bursts, by a Gilbert-Elliott two-state model.

Peers: toxiproxy's ``packet_loss`` with its Gilbert-Elliott burst model (PR #739). The line
is in a good or a bad state; after each unit (a byte, or a whole chunk with ``unit =
"chunk"``) it goes bad with ``p_good_to_bad`` or back with ``p_bad_to_good`` (so a bad
spell lasts 1 / p_bad_to_good units on average), and a unit is lost with ``loss_good`` or
``loss_bad``. It starts good; the state advances only over chunks inside an episode. One
ledger entry per run of adjacent lost bytes (``removed``), as for byte_drop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import between, key, one_of

from .base import LineFault
from .line import FaultWrapper, remove

NEVER = 1 << 62


@dataclass(frozen=True, kw_only=True)
class BurstLoss(LineFault):
    """Burst loss (Gilbert-Elliott): a good and a bad state with their own loss."""
    KIND = "burst_loss"
    p_good_to_bad: float = key(0.001, "", "per unit: the chance the good state turns bad",
                               between(0, 1))
    p_bad_to_good: float = key(0.1, "", "per unit: the chance the bad state ends",
                               between(0, 1))
    loss_good: float = key(0.0, "", "chance a unit is lost in the good state", between(0, 1))
    loss_bad: float = key(1.0, "", "chance a unit is lost in the bad state", between(0, 1))
    unit: str = key("byte", "", "what a step and a loss are: a byte or a whole chunk",
                    one_of("byte", "chunk"))

    def wrapper(self, rng):
        return _BurstLoss(self, rng)


class _BurstLoss(FaultWrapper):
    def __init__(self, fault, rng) -> None:
        super().__init__(fault, rng)
        self.bad = False
        self.left = self._sojourn()  # units left in this state

    def _sojourn(self) -> int:
        p = self.fault.p_bad_to_good if self.bad else self.fault.p_good_to_bad
        return int(self.rng.geometric(p)) if p > 0 else NEVER

    def _lost(self, n: int) -> list[int]:
        """Which of the next *n* units are lost."""
        lost, i = [], 0
        while i < n:
            m = min(self.left, n - i)
            loss = self.fault.loss_bad if self.bad else self.fault.loss_good
            if loss >= 1:
                lost.extend(range(i, i + m))
            elif loss > 0:
                lost.extend((i + np.flatnonzero(self.rng.random(m) < loss)).tolist())
            i += m
            self.left -= m
            if not self.left:
                self.bad = not self.bad
                self.left = self._sojourn()
        return lost

    def act(self, start_ns, data, baud):
        if self.fault.unit == "chunk":
            lost = range(len(data)) if self._lost(1) else ()
        else:
            lost = self._lost(len(data))
        out, runs = remove(data, lost)
        for at, n in runs:
            self.mark(start_ns, at, at, removed=n)
        return start_ns, out
