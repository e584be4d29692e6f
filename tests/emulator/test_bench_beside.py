"""emulator-jitter beside another scenario or timing mode: one invocation runs each scenario
of ``--scenarios`` in turn, in each mode of ``--timings``, and gives a row each and their p99s
against the first's."""
import pytest

from navtwin.cli.bench import available, settings
from navtwin.cli.main import UsageError
from navtwin.emulator import bench


def test_a_row_per_scenario_and_the_p99_ratios(monkeypatch):
    runs = []

    def fake(seconds, scenario, timing):
        runs.append((seconds, scenario, timing))
        p99 = {"office": 0.2, "outage-bridging": 0.3}[scenario]
        return {"benchmark": "jitter", "scenario": scenario, "timing": "fifo", "p99_ms": p99,
                "emulator_late_p99_ms": p99 / 10}

    monkeypatch.setattr(bench, "jitter", fake)
    run = available()["emulator-jitter"]
    out = run(False, settings("emulator-jitter", run.Settings, {"seconds": "5", "scenarios": "office,outage-bridging"}))
    assert runs == [(5.0, "office", "auto"), (5.0, "outage-bridging", "auto")]
    assert [r["scenario"] for r in out["rows"]] == ["office", "outage-bridging"]
    ratio = out["p99_ratio_to_first"]["outage-bridging/fifo"]
    assert ratio == {"p99_ms": pytest.approx(1.5), "emulator_late_p99_ms": pytest.approx(1.5)}


def test_a_row_per_timing_mode_beside_the_first(monkeypatch):
    runs = []

    def fake(seconds, scenario, timing):
        runs.append(timing)
        p99 = {"fifo": 0.1, "slack": 0.2, "spin": 0.4}[timing]
        return {"benchmark": "jitter", "scenario": scenario, "timing": timing, "p99_ms": p99,
                "emulator_late_p99_ms": p99}

    monkeypatch.setattr(bench, "jitter", fake)
    run = available()["emulator-jitter"]
    out = run(False, settings("emulator-jitter", run.Settings,
                              {"seconds": "5", "timings": "fifo,slack,spin"}))
    assert runs == ["fifo", "slack", "spin"]
    assert {k: v["p99_ms"] for k, v in out["p99_ratio_to_first"].items()} == \
        {"office/slack": pytest.approx(2.0), "office/spin": pytest.approx(4.0)}


def test_an_unknown_timing_mode_is_one_line():
    run = available()["emulator-jitter"]
    with pytest.raises(UsageError, match="timings.*fifo,slack,spin"):
        settings("emulator-jitter", run.Settings, {"timings": "fifo,fast"})


@pytest.mark.pty
def test_the_pty_floor_writes_and_reads_every_frame_of_each_pair():
    run = available()["pty-floor"]
    out = run(False, settings("pty-floor", run.Settings, {"seconds": "2"}))
    pairs = out["bare_pty"]
    assert {k: (b["frames"], b["lost"]) for k, b in pairs.items()} == \
        {"10 ms": (200, 0), "25 ms": (80, 0)}
    for b in pairs.values():  # figures of real arrivals: ordered, and none before its write
        assert 0 <= b["p50_ms"] <= b["p99_ms"] <= b["max_ms"]
        assert 0 <= b["late_p50_ms"] <= b["late_p99_ms"] <= b["late_max_ms"]
