"""A track sees the estimator only through its declared TrackContext (host/tracks/base.py):
a track written against the declared members runs; one that reaches for anything else, or
writes what it reads, fails at once with an AttributeError (docs/architecture.md)."""
from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

from navtwin.host import tracks
from navtwin.host.estimator import Estimator
from navtwin.host.settings import EstimatorConfig
from navtwin.host.measurements import Exchange, Fix, ImuSample, Motion
from navtwin.host.tracks.base import Track, TrackContext, estimate

from ..helpers import GRAVITY, OFFICE_ANCHORS

#: What a track may use: the declaration docs/architecture.md and docs/filters.md list.
DECLARED = {"cfg", "model", "layout", "calibration", "t", "stale", "on_innovation",
            "sins", "origin", "t_imu", "t_aligned", "fixes"}
AT = (6.0, 3.0)  # where the vehicle stands (m)
ALIGN_S = 1.0


def test_the_context_exposes_exactly_the_declared_members_each_documented():
    public = {n for n in dir(TrackContext) if not n.startswith("_")}
    assert public == DECLARED
    for name in DECLARED:
        assert inspect.getdoc(getattr(TrackContext, name)), f"{name} has no docstring"


def cfg(*filters: str) -> EstimatorConfig:
    return EstimatorConfig(anchors=OFFICE_ANCHORS, alignment_s=ALIGN_S, start=AT, filters=filters)


def standing(seconds: float) -> list:
    """A vehicle standing at AT: IMU at 100 Hz (gravity only), one exchange per anchor per
    0.1 s cycle, exact distances: records in time order."""
    out = [(k * 0.01, ImuSample(k * 0.01, (0.0, 0.0, 0.0), (0.0, 0.0, GRAVITY)))
           for k in range(round(seconds * 100))]
    for k in range(round(seconds * 10)):
        for j, (a, (x, y, z)) in enumerate(sorted(OFFICE_ANCHORS.items())):
            t = k * 0.1 + 0.005 + j * 0.025
            out.append((t, Exchange(t, a, math.dist((x, y, z), (*AT, 0.0)))))
    return [r for _, r in sorted(out, key=lambda p: p[0])]


class Reader(Track):
    """Written against the declared context only: every member, read."""

    name = "reader"
    uses_strapdown = True  # so the estimator aligns and runs its strapdown

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.seen: list[tuple] = []

    def handlers(self):
        return {Fix: self.fix, Motion: self.motion}

    def motion(self, m: Motion) -> None:
        ctx = self.ctx
        assert ctx.t == m.t
        self.seen.append(("motion", m.kind, ctx.sins is not None, ctx.t_aligned))

    def fix(self, fix: Fix) -> None:
        ctx = self.ctx
        assert ctx.fixes[-1] is fix and ctx.layout.ids == (1, 2, 3, 4)
        assert ctx.cfg.start == AT and ctx.calibration is None and ctx.on_innovation is None
        self.seen.append(("fix", fix.t))

    def estimate(self, b: float, yaw: float):
        ctx = self.ctx
        if not ctx.fixes:
            return None
        x, _ = ctx.model.propagate(np.array([*ctx.fixes[-1].p, 0, 0, 0, 0]), np.zeros((6, 6)), 0.0)
        return estimate(b, self.name, x[:2], (0.0, 0.0), yaw, [0.0] * 16,
                        ctx.stale(b, ctx.fixes[-1].t))


class Reacher(Reader):
    """Reaches past the context for the estimator's ranging part (its cycles, its solver)."""

    name = "reacher"

    def fix(self, fix: Fix) -> None:
        self.ctx.ranging  # noqa: B018 - the attribute access is what fails


class Writer(Reader):
    """Writes the filter time it may only read."""

    name = "writer"

    def fix(self, fix: Fix) -> None:
        self.ctx.t = fix.t


@pytest.fixture
def registered():
    added = [tracks.register(cls) for cls in (Reader, Reacher, Writer)]
    yield
    for cls in added:
        tracks.unregister(cls.name)


def test_a_track_written_against_the_context_runs_and_sees_the_shared_state(registered):
    est = Estimator(cfg("reader"))
    out = [e for r in standing(3.0) for e in est.feed(r)]
    track = est.tracks[0]
    assert isinstance(track.ctx, TrackContext) and track.ctx is est.context
    kinds = [s[1] for s in track.seen if s[0] == "motion"]
    assert kinds[0] == "stationary" and kinds[-1] == "accel"  # the alignment ended
    assert all(s[2] == (s[1] == "accel") for s in track.seen if s[0] == "motion")
    assert sum(s[0] == "fix" for s in track.seen) == 30  # one fix per cycle (3 s of 0.1 s)
    assert out and all(e.filter == "reader" for e in out)
    assert out[-1].x == pytest.approx(AT[0], abs=1e-6) and out[-1].y == pytest.approx(AT[1], abs=1e-6)
    assert not out[-1].extrapolated


@pytest.mark.parametrize("name", ["reacher", "writer"])
def test_a_track_touching_an_undeclared_member_or_writing_one_fails_loudly(registered, name):
    est = Estimator(cfg(name))
    with pytest.raises(AttributeError, match="'TrackContext' object has no attribute 'ranging'|"
                                             "property 't' of 'TrackContext' object has no setter"):
        for r in standing(1.0):
            est.feed(r)


class Waiter(Reader):
    """Starts again from a fix after each discontinuity (the fusion tracks' way)."""

    name = "waiter"

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.started_at: list[float] = []

    def reinit_at(self, fix: Fix) -> bool:
        self.started_at.append(fix.t)
        return True


def test_a_discontinuity_is_counted_once_and_ends_at_the_first_fix_no_older_than_it():
    tracks.register(Waiter)
    try:
        est = Estimator(cfg("waiter"))
        track = est.tracks[0]
        records = standing(2.0)
        for r in records[:len(records) // 2]:
            est.feed(r)
        t = est.time.t
        track.discontinuity("gated", t)
        track.discontinuity("gap", t + 0.01)  # a second cause before the fix: still one
        assert track.pending and est.reinit_count == 1 and track.reinits == {"gated": 1}
        for r in records[len(records) // 2:]:
            est.feed(r)
        assert len(track.started_at) == 1 and track.started_at[0] >= t + 0.01
        assert not track.pending and track.reinit_fix.t == track.started_at[0]
        assert est.stats()["reinit"] == {"waiter": {"gated": 1}} and est.stats()["reinit_pending"] == []
    finally:
        tracks.unregister("waiter")
