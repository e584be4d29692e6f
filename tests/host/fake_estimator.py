"""A stand-in for host.estimator.Estimator that records what the pipeline gives it.

Its estimates are a simple deterministic function of its inputs (mean specific force,
last range per anchor), one per output period of filter time, so output equality checks
mean something without the real filters; ``calls`` lets tests check times and order.
"""
from __future__ import annotations

from host.estimator import Estimate


class RecordingEstimator:
    def __init__(self, filters=("kf",), output_period_s: float = 0.1) -> None:
        self.filters = tuple(filters)
        self.period = output_period_s
        self.calls: list[tuple] = []
        self._next = None
        self._ranges: dict[int, float] = {}
        self._az = 0.0
        self.reinit_count = 0

    def _out(self, t: float) -> list:
        if self._next is None:
            self._next = t + self.period
            return []
        if t < self._next:
            return []
        self._next += self.period
        x = sum(self._ranges.values())
        return [Estimate(t, f, x, self._az, 0.0, 0.0, 0.0, ((1.0, 0.0), (0.0, 1.0)))
                for f in self.filters]

    def imu(self, t, gyro, accel, nd_ok=True) -> list:
        self.calls.append(("imu", t, tuple(gyro), tuple(accel), nd_ok))
        self._az += accel[2]
        return self._out(t)

    def range(self, t, anchor, distance, rssi, status) -> list:
        self.calls.append(("range", t, anchor, distance, rssi, status))
        if distance is not None:
            self._ranges[anchor] = distance
        return self._out(t)

    def restart(self, t, device, uptime_s=0.0) -> list:
        self.calls.append(("restart", t, device, uptime_s))
        return self._out(t)

    def stats(self) -> dict:
        return {"calls": len(self.calls)}
