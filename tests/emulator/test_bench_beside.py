"""emulator-jitter beside another scenario: one invocation runs each scenario of
``--scenarios`` in turn and gives a row each and their p99s against the first's."""
import pytest

from navtwin.cli.bench import available, settings
from navtwin.emulator import bench


def test_a_row_per_scenario_and_the_p99_ratios(monkeypatch):
    runs = []

    def fake(seconds, scenario):
        runs.append((seconds, scenario))
        p99 = {"office": 0.2, "outage-bridging": 0.3}[scenario]
        return {"benchmark": "jitter", "scenario": scenario, "p99_ms": p99, "emulator_late_p99_ms": p99 / 10}

    monkeypatch.setattr(bench, "jitter", fake)
    run = available()["emulator-jitter"]
    out = run(False, settings("emulator-jitter", run.Settings, {"seconds": "5", "scenarios": "office,outage-bridging"}))
    assert runs == [(5.0, "office"), (5.0, "outage-bridging")]
    assert [r["scenario"] for r in out["rows"]] == ["office", "outage-bridging"]
    ratio = out["p99_ratio_to_first"]["outage-bridging"]
    assert ratio == {"p99_ms": pytest.approx(1.5), "emulator_late_p99_ms": pytest.approx(1.5)}
