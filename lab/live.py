"""The lab while it runs: each track's error against truth, from the files both sides write.

Truth leaves the emulator only as its recording's ``truth.csv`` (flushed about once a second)
and the host's estimates only as its output file, so the live view tails both, as a user's
script would: :class:`Tail` yields the complete lines added since the last call, and
:class:`LiveErrors` compares each new estimate with the truth at its scenario time
(``host time + offset``) once the truth file has reached that time. Memory stays bounded:
only the last ``KEEP_TRUTH_S`` of truth is kept.
"""
from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import evaluate

KEEP_TRUTH_S = 30.0  # truth kept behind its newest row; an estimate older than that is not compared


class Tail:
    """The complete lines appended to a growing file since the last call (none while it is
    missing; a partial last line waits for its newline)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._pos = 0
        self._part = b""

    def lines(self) -> list[str]:
        try:
            with open(self.path, "rb") as f:
                f.seek(self._pos)
                data = f.read()
        except FileNotFoundError:
            return []
        self._pos += len(data)
        *whole, self._part = (self._part + data).split(b"\n")
        return [line.decode("utf-8", "replace") for line in whole if line.strip()]


@dataclass
class TrackError:
    """One track's error against truth so far (m)."""

    n: int = 0
    last: float = float("nan")
    total: float = 0.0
    max: float = 0.0

    @property
    def mean(self) -> float:
        return self.total / self.n if self.n else float("nan")


class LiveErrors:
    """A vehicle's tracks against the truth of a running lab: *truth_csv* is its truth file,
    *vehicle* its number in the *estimates* file (its host's config order)."""

    def __init__(self, truth_csv: str | Path, estimates: str | Path, vehicle: int = 1) -> None:
        self.vehicle = vehicle
        self._truth = Tail(truth_csv)
        self._estimates = Tail(estimates)
        self._cols: tuple[int, int, int] | None = None  # t, x, y in truth.csv's header
        self._t = np.empty(0)
        self._x = np.empty(0)
        self._y = np.empty(0)
        self._waiting: deque[str] = deque()
        self.tracks: dict[str, TrackError] = {}

    def _read_truth(self) -> None:
        lines = self._truth.lines()
        if lines and self._cols is None:
            header = lines.pop(0).split(",")
            self._cols = (header.index("t"), header.index("x"), header.index("y"))
        if not lines:
            return
        rows = np.array([[float(v) for v in (r.split(",")[c] for c in self._cols)]
                         for r in lines])
        self._t = np.concatenate((self._t, rows[:, 0] / 1e9))
        self._x = np.concatenate((self._x, rows[:, 1]))
        self._y = np.concatenate((self._y, rows[:, 2]))

    def update(self, offset_s: float | None) -> dict[str, TrackError]:
        """Take what both files gained; *offset_s* maps host time to scenario time (None
        while it is not known: estimates wait)."""
        self._read_truth()
        self._waiting.extend(self._estimates.lines())
        if offset_s is None or not self._t.size:
            return self.tracks
        truth = {"t": self._t, "x": self._x, "y": self._y}
        ready = evaluate.load_estimates(self._take_ready(offset_s), self.vehicle)
        for name, e in sorted(ready.items()):
            err = evaluate.error(truth, e, offset_s)
            tr = self.tracks.setdefault(name, TrackError())
            tr.n += err.size
            tr.total += float(err.sum())
            tr.max = max(tr.max, float(err.max()))
            tr.last = float(err[-1])
        keep = self._t >= self._t[-1] - KEEP_TRUTH_S
        self._t, self._x, self._y = self._t[keep], self._x[keep], self._y[keep]
        return self.tracks

    def _take_ready(self, offset_s: float) -> list[str]:
        """Waiting lines whose scenario time the truth has reached (in order; lines before
        the truth kept are dropped: they cannot be compared)."""
        out = []
        while self._waiting:
            t = json.loads(self._waiting[0])["t"] + offset_s
            if t > self._t[-1]:
                break
            line = self._waiting.popleft()
            if t >= self._t[0]:
                out.append(line)
        return out
