"""A starved host reaches the same estimates, late: the same bytes with multi-second stalls
in their arrival stamps (every port late together, as when the host gets no CPU) give the
estimates and the NEES of the unstalled replay (docs/host.md, "A starved host")."""
import math

import numpy as np
import pytest

from navtwin.host.estimator import Estimator
from navtwin.host.output import estimate_line
from navtwin.host.pipeline import Pipeline
from navtwin.host.replay import drive
from navtwin.lab import evaluate
from navtwin.lab.run import lab_chunks, truth

SEED = 4
DURATION_S = 20.0


def stalled(chunks, start_s: float, stall_s: float, catch_up: float):
    """*chunks* as a host starved from *start_s* reads them: nothing for *stall_s*, then the
    backlog, read in *catch_up* of the time it took to send (0: in one burst) until it has
    caught up; bytes and order intact, stamps strictly increasing."""
    start, stall = int(start_s * 1e9), int(stall_s * 1e9)
    last = -1
    for port, data, t_ns in chunks:
        if t_ns >= start:
            t_ns = max(t_ns, start + stall + int((t_ns - start) * catch_up))
        last = max(t_ns, last + 1)
        yield port, data, last


class Calls(Estimator):
    """The estimator, noting each record it is given: (type, time)."""

    def feed(self, record):
        self.calls.append((type(record).__name__, record.t))
        return super().feed(record)


def run(kw: dict, chunks) -> tuple[list, Pipeline, list]:
    kw = dict(kw)
    calls: list = []

    def make(cfg):
        est = Calls(cfg)
        est.calls = calls
        return est

    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), make_estimator=make, **kw)
    estimates: list = []
    drive(pipe, chunks, estimates.extend)
    return estimates, pipe, calls


@pytest.fixture(scope="module")
def lab():
    kw, chunks = lab_chunks("office", SEED, duration=DURATION_S)
    chunks = list(chunks)
    return kw, chunks, run(kw, chunks), truth("office", SEED)


def nees(estimates, tr) -> dict:
    errors = evaluate.position_errors(tr, evaluate.load_estimates(map(estimate_line, estimates)))
    return {name: e["nees_mean"] for name, e in errors.items()}


@pytest.mark.parametrize("start_s, stall_s, catch_up", [
    (6.0, 3.0, 0.0),  # 3 s without a read, then the backlog at once
    (9.0, 2.5, 0.5),  # then read at twice the line's pace: over 1 s late for 3 s of reads
    (13.0, 4.0, 0.0),
])
def test_stalled_arrivals_give_the_same_estimates_and_nees(lab, start_s, stall_s, catch_up):
    kw, chunks, (want, want_pipe, want_calls), tr = lab
    got, pipe, calls = run(kw, stalled(chunks, start_s, stall_s, catch_up))
    # the same records reach the estimator in the same order, at the same times (to 0.1 ms)
    assert [c[0] for c in calls] == [c[0] for c in want_calls]
    assert np.abs(np.array([c[1] for c in calls]) - [c[1] for c in want_calls]).max() < 1e-4
    # no clock was taken for stepped or restarted
    for stats in (pipe.stats()["anchor_clock"], pipe.stats()["vehicles"][0]["imu_clock"]):
        assert stats["clock_resets"] == 0 and stats["restarts"] == 0
    assert len(got) == len(want)
    worst: dict = {}
    for a, b in zip(want, got):
        assert (a.filter, a.t) == (b.filter, b.t)
        worst[a.filter] = max(worst.get(a.filter, 0.0), math.hypot(a.x - b.x, a.y - b.y))
    print(worst)
    assert all(d < 1e-3 for d in worst.values()), worst
    want_nees, got_nees = nees(want, tr), nees(got, tr)
    assert got_nees == pytest.approx(want_nees, rel=1e-3, nan_ok=True)


def test_a_host_that_starts_late_aligns_on_the_rest_of_the_stationary_start(lab):
    # started under load, the host opens its ports 2.5 s after the board's power-up: it
    # aligns over what is left of the 8 s the vehicle stands still, not over 8 s from its
    # first sample (2.5 s of them moving: a tilt error, SINS acceleration off, NEES 8x)
    kw, chunks, (want, _, _), tr = lab
    got, _, _ = run(kw, [c for c in chunks if c[2] >= 2.5e9])
    want_nees, got_nees = nees(want, tr), nees(got, tr)
    print(want_nees, got_nees)
    for name in ("kf", "ekf", "ukf"):
        assert got_nees[name] < 1.5 * want_nees[name], (name, got_nees, want_nees)
