"""A stand-in for host.estimator.Estimator that records what the pipeline gives it.

Its estimates are a simple deterministic function of its inputs (mean specific force,
last range per anchor), one per output period of filter time, so output equality checks
mean something without the real filters; ``calls`` lets tests check times and order.
"""
from __future__ import annotations

from navtwin.host.estimator import Estimate
from navtwin.host.measurements import AnchorExchange, Exchange, ImuSample


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

    def feed(self, r) -> list:
        if isinstance(r, ImuSample):
            self.calls.append(("imu", r.t, tuple(r.gyro), tuple(r.accel), r.nd_ok))
            self._az += r.accel[2]
        elif isinstance(r, Exchange):
            self.calls.append(("range", r.t, r.anchor, r.distance, r.rssi, r.status))
            if r.distance is not None:
                self._ranges[r.anchor] = r.distance
        elif isinstance(r, AnchorExchange):
            self.calls.append(("anchors", r.t, r.anchor, r.other, r.distance, r.rssi, r.status))
        else:
            self.calls.append(("restart", r.t, r.device, r.uptime_s))
        return self._out(r.t)

    def imu_gaps(self) -> dict:  # the service's status line asks, once a status period passed
        return {"bridged": 0, "reinit": 0}

    def stats(self) -> dict:
        return {"calls": len(self.calls)}
