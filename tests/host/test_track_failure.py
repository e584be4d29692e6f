"""A track that fails is off until the next fix; the other tracks and the host run on."""
from __future__ import annotations

import dataclasses
import math

import pytest

from navtwin.host import tracks
from navtwin.host.tracks.wsn import WsnTrack
from navtwin.lab.run import run_in_memory


class Brittle(WsnTrack):
    """The wsn track, whose 30th fix and 50th estimate fail as a diverged filter's do."""

    name = "brittle"

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.fixes = self.estimates = 0

    def fix(self, fix) -> None:
        self.fixes += 1
        if self.fixes == 30:
            math.sqrt(-1.0)  # ValueError: math domain error
        super().fix(fix)

    def estimate(self, b, yaw):
        self.estimates += 1
        e = super().estimate(b, yaw)
        if self.estimates == 50 and e is not None:
            return dataclasses.replace(e, x=math.nan)
        return e


@pytest.fixture
def brittle():
    tracks.TRACKS.register("brittle", Brittle)
    yield
    tracks.TRACKS.unregister("brittle")


def test_a_failing_track_restarts_and_the_others_run_on(brittle):
    est, pipe = run_in_memory("office", 1, filters=("wsn", "brittle", "kf"), duration=12)
    counts = {n: sum(1 for e in est if e.filter == n) for n in ("wsn", "brittle", "kf")}
    stats = pipe.vehicles[0].estimator.stats()
    assert stats["reinit"]["brittle"]["error"] == 2  # the fix, then the estimate
    assert stats["track_errors"]["brittle"].startswith("FloatingPointError: estimate (nan,")
    assert "wsn" not in stats["reinit"] and counts["kf"] > 100 and counts["wsn"] > 100
    assert 0 < counts["brittle"] < counts["wsn"]  # off for a moment, then on again
    assert all(math.isfinite(e.x) for e in est)
