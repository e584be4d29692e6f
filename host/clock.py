"""Device counters and clocks on the host timeline.

The host sees two device clocks: the SINS board's sample counter (16 bits, one tick per
sample, 10 ms nominal on the board's crystal) and the anchor network's time ``t_us``
(32 bits, microseconds on the anchors' shared wired clock). Neither knows the host clock.
Each measurement also has an arrival stamp: host monotonic time since the run started,
taken when the chunk holding its last byte was read.

Unwrapping (:class:`Unwrapper`). A raw counter value r is congruent mod 2^bits to the true
count; of the candidates ``last + d + n 2^bits`` (d = (r - r_last) mod 2^bits) the one
nearest to what the elapsed arrival time predicts, ``(a - a_last) / tick``, is taken. A
count is therefore right across any number of wraps and any outage, as long as arrival
times are good to half a wrap (327 s for the SINS counter, 35 min for ``t_us``). A count
that steps back, or comes early, by more than ``restart`` ticks against that prediction
cannot come from a device that kept counting: it restarted, and a new epoch begins. A count
that moves forward but less than predicted is late, not new: the bytes waited while the
host or the line stalled (a restart that happens to land there, a chance of about its gap in
half a wrap, goes unseen as such). A counter without a tick, such as the gateway's report
number, restarts when it steps back by more than ``restart``. A new epoch
re-anchors the device's times on arrival times, so even a wrong guess of a restart keeps
the host timeline whole.

Alignment (:class:`ClockAligner`). Arrival = send time + delay, delay >= d_min, so the
points (device time t, lag = arrival - t) lie on or above the line
``lag = offset + rate * t`` of the minimum-delay envelope. The points are grouped in
blocks of ``block_s`` of device time; the lowest point of each block (after removing the
current rate) is kept for the last ``window`` blocks. Once ``min_blocks`` are complete,
the rate is the slope of the line under all those minima that is highest at their mean
time (the lower convex hull's edge there: the linear-programming fit of the minimum-delay
envelope), bounded by ``max_rate`` (crystals are good to 1e-4); before that it is 0. The
offset puts the line under all of them, then under every newer point as it comes. The host
time of device time t is ``t + offset + rate * t``: the earliest time the measurement could
have arrived. Late points (a host that got no CPU for seconds, a slow line) lie above the
line and move neither rate nor offset, however late and for however long, as long as the
points that came on time still span the middle of the window. A point more than ``step_s``
below the line means the device clock jumped ahead: the estimate starts over. A point far
above it is only late: a device clock that steps back is a restart for the Unwrapper.

:class:`DeviceClock` combines the two with the rule that a stream's host times never step
back: the filters see each stream in its own order.
"""
from __future__ import annotations

import math
from collections import deque

MIN_STEP_S = 1e-6  # between two samples of a strict stream, should the envelope move back


class Unwrapper:
    """A wrapping counter -> an unbounded count, using arrival times to resolve wraps."""

    def __init__(self, bits: int, tick_s: float | None = None, restart: int | None = None) -> None:
        self.modulus = 1 << bits
        self.tick_s = tick_s  # None: no time per tick; one tick is expected between values
        self.restart = restart  # ticks off the prediction that start a new epoch; None: never
        self.last: int | None = None  # the newest count so far
        self._raw = 0
        self._arrival = 0.0
        self.restarts = 0

    def unwrap(self, raw: int, arrival_s: float) -> tuple[int, int | None]:
        """(count, step): step = count - the newest count before, or None when *raw*
        begins an epoch (the first value, or a restart)."""
        if self.last is not None:
            m = self.modulus
            d = (raw - self._raw) % m
            expected = (arrival_s - self._arrival) / self.tick_s if self.tick_s else 1.0
            value = self.last + d + m * math.floor((expected - d) / m + 0.5)
            step = value - self.last
            off = step - expected if self.tick_s else max(-step, 0)
            # a count forward but behind the prediction came late (the host or the line
            # stalled and the bytes waited): only a step back or a count early is a restart
            if self.restart is None or abs(off) <= self.restart or 0 < step < expected:
                if step > 0:
                    self.last, self._raw, self._arrival = value, raw, arrival_s
                return value, step
            self.restarts += 1
        self.last, self._raw, self._arrival = raw, raw, arrival_s
        return raw, None


class ClockAligner:
    """Online minimum-delay envelope of arrival vs device time: offset and rate."""

    def __init__(self, block_s: float = 1.0, window: int = 30, step_s: float = 1.0,
                 max_rate: float = 1e-3, min_blocks: int = 5) -> None:
        self.block_s = block_s
        self.min_blocks = min_blocks
        self.step_s = step_s
        self.max_rate = max_rate
        self._minima: deque[tuple[float, float]] = deque(maxlen=window)
        self.resets = 0
        self.reset(count=False)

    def reset(self, count: bool = True) -> None:
        self._minima.clear()
        self._block: int | None = None
        self._open: tuple[float, float] | None = None  # (t, lag) minimum of the open block
        self.rate = 0.0
        self.offset: float | None = None
        self.resets += count

    def add(self, device_s: float, arrival_s: float) -> None:
        lag = arrival_s - device_s
        # far below the line: the device clock jumped ahead. Far above is only late (the host
        # or the line stalled): a clock that steps back is the Unwrapper's restart
        if self.offset is not None and lag - self.offset - self.rate * device_s < -self.step_s:
            self.reset()
        block = math.floor(device_s / self.block_s)
        low = lag - self.rate * device_s
        if block != self._block:
            if self._open is not None:
                self.close_block(self._open)
                low = lag - self.rate * device_s
            self._block, self._open = block, (device_s, lag)
        elif low < self._open[1] - self.rate * self._open[0]:
            self._open = (device_s, lag)
        if self.offset is None or low < self.offset:
            self.offset = low

    def close_block(self, minimum: tuple[float, float]) -> None:
        """The open block ends with its lowest point *minimum* (device t, lag): the window's
        fit of rate and offset (host.batch.chunks replays the blocks of a run this way)."""
        self._minima.append(minimum)
        self._fit()

    def _fit(self) -> None:
        pts = sorted(self._minima)
        if len(pts) >= self.min_blocks:
            self.rate = min(max(_envelope_slope(pts), -self.max_rate), self.max_rate)
        self.offset = min(v - self.rate * t for t, v in pts)

    def to_host(self, device_s: float) -> float:
        return device_s + self.offset + self.rate * device_s


def _envelope_slope(pts: list[tuple[float, float]]) -> float:
    """The slope of the line under all *pts* (sorted by t) that is highest at their mean t:
    the lower convex hull's edge there. Points above the hull (late ones) do not move it."""
    hull: list[tuple[float, float]] = []
    for p in pts:
        while len(hull) >= 2 and ((hull[-1][0] - hull[-2][0]) * (p[1] - hull[-2][1])
                                  - (hull[-1][1] - hull[-2][1]) * (p[0] - hull[-2][0])) <= 0:
            hull.pop()
        hull.append(p)
    tm = sum(t for t, _ in pts) / len(pts)
    for (t0, v0), (t1, v1) in zip(hull, hull[1:]):
        if t1 >= tm and t1 > t0:
            return (v1 - v0) / (t1 - t0)
    return 0.0


class DeviceClock:
    """A device counter -> host time (s since start): unwrap, align, never step back.

    ``strict``: a count that is not newer than the newest is a duplicate and is refused
    (SINS samples); otherwise an older count keeps its own, older, host time (exchange
    times). Gaps in a strict counter are counted as ``lost``.
    """

    def __init__(self, bits: int, tick_s: float, *, strict: bool, restart_s: float = 1.0,
                 **aligner) -> None:
        self.tick_s = tick_s
        self.strict = strict
        self.counter = Unwrapper(bits, tick_s, restart=max(1, round(restart_s / tick_s)))
        self.aligner = ClockAligner(**aligner)
        self._base = 0
        self.last_t = -math.inf
        self.lost = 0
        self.duplicates = 0

    def time(self, raw: int, arrival_s: float) -> float | None:
        value, step = self.counter.unwrap(raw, arrival_s)
        if step is None:
            self._base = value
            if self.counter.restarts:
                self.aligner.reset()
        elif step <= 0 and self.strict:
            self.duplicates += 1
            return None
        elif step > 1 and self.strict:
            self.lost += step - 1
        device_s = (value - self._base) * self.tick_s
        self.aligner.add(device_s, arrival_s)
        t = self.aligner.to_host(device_s)
        if step is None or step > 0:
            # a strict stream's times strictly increase (the SINS integrates their differences)
            t = max(t, self.last_t + MIN_STEP_S) if self.strict else max(t, self.last_t)
            self.last_t = t
        return t

    @property
    def restarts(self) -> int:
        """New epochs after the first: the device restarted (or seemed to)."""
        return self.counter.restarts

    def stats(self) -> dict:
        a = self.aligner
        return {"rate_ppm": a.rate * 1e6, "offset_ms": None if a.offset is None else a.offset * 1e3,
                "lost": self.lost, "duplicates": self.duplicates,
                "restarts": self.counter.restarts, "clock_resets": a.resets}
