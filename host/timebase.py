"""The estimator's time base: the filter time, the output instants, and when an estimate is
extrapolated (docs/filters.md)."""
from __future__ import annotations

import math


class FilterTime:
    """The fusion's clock, driven by the measurements alone (no wall clock).

    Owns ``t`` (the filter time: the latest measurement's), ``t_first`` (the first
    measurement's: the configured start counts as aiding then) and ``next_out``, the next
    output instant: k * output_period_s, the first one at or after the first measurement."""

    def __init__(self, output_period_s: float, extrapolated_after_s: float) -> None:
        self.output_period_s = output_period_s
        self.extrapolated_after_s = extrapolated_after_s
        self.t: float | None = None
        self.t_first: float | None = None
        self._k_out = 0
        self.next_out = 0.0

    def advance(self, t: float) -> None:
        """A measurement at t: the filter time is the latest one's (a late one leaves it)."""
        self.t = max(self.t, t)

    def start(self, t: float) -> None:
        """The first measurement, at t: every clock starts there."""
        self.t = self.t_first = t
        self._k_out = math.ceil(t / self.output_period_s)
        self.next_out = self._k_out * self.output_period_s

    def next_instant(self) -> None:
        """The output instant ``next_out`` is done: the next one (k, not a running sum)."""
        self._k_out += 1
        self.next_out = self._k_out * self.output_period_s

    def stale(self, b: float, t_aided: float | None) -> bool:
        """Whether an estimate at b, last aided at t_aided (None: never, only the configured
        start at the first measurement), is extrapolated."""
        return b - (self.t_first if t_aided is None else t_aided) > self.extrapolated_after_s
