"""Node clocks and serial queues, in integer nanoseconds of true time (8N1 byte timing:
protocols.serial).

A node whose crystal runs fast by ``ppm`` measures a true interval T as T (1 + ppm 1e-6);
a schedule of ticks every P of its own clock therefore falls at true times
``t0 + round(k P / (1 + ppm 1e-6))``: an absolute schedule, so drift never accumulates
rounding and the k-th tick does not depend on how the ticks were generated in blocks.
"""
from __future__ import annotations

import math

import numpy as np



class Clock:
    """A free-running crystal: ``ppm`` offset, ticks of ``period_ns`` (its own ns) from true
    time ``t0_ns``."""

    def __init__(self, ppm: float, period_ns: float, t0_ns: int = 0) -> None:
        self.ppm = ppm
        self.scale = 1.0 + ppm * 1e-6
        self.period_ns = period_ns
        self.true_period_ns = period_ns / self.scale
        self.t0_ns = int(t0_ns)

    def tick(self, k):
        """True time (ns) of tick *k* (int or int array)."""
        if isinstance(k, np.ndarray):
            return self.t0_ns + np.rint(k * self.true_period_ns).astype(np.int64)
        return self.t0_ns + int(round(k * self.true_period_ns))

    def ticks_between(self, lo_ns: int, hi_ns: int) -> np.ndarray:
        """Tick numbers k >= 0 with lo_ns <= tick(k) < hi_ns."""
        k0 = max(0, math.floor((lo_ns - self.t0_ns) / self.true_period_ns) - 1)
        while self.tick(k0) < lo_ns:
            k0 += 1
        k1 = max(k0, math.floor((hi_ns - self.t0_ns) / self.true_period_ns) - 1)
        while self.tick(k1) < hi_ns:
            k1 += 1
        return np.arange(k0, k1, dtype=np.int64)


def serial_queue(ready: np.ndarray, durations: np.ndarray, busy_until: int) -> tuple[np.ndarray, np.ndarray]:
    """Start and end times of jobs served one at a time in order (a UART, a radio).

    Job i starts at max(ready_i, end_{i-1}) and takes durations_i; the server is busy until
    *busy_until* before the first job. Vectorised max-plus scan:
    end_i = C_i + max(busy_until, max_{j<=i}(ready_j - C_{j-1})), C = cumsum(durations).
    """
    ready = np.asarray(ready, dtype=np.int64)
    durations = np.asarray(durations, dtype=np.int64)
    if ready.size == 0:
        return ready.copy(), ready.copy()
    c = np.cumsum(durations)
    c_before = c - durations
    end = c + np.maximum(busy_until, np.maximum.accumulate(ready - c_before))
    return end - durations, end
