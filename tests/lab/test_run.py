"""The in-memory run gives exactly what recording the emulator and replaying it gives."""
import pytest

from navtwin.host.output import estimate_line
from navtwin.lab.run import run_in_memory
from tests.reference import estimate_lines


@pytest.mark.parametrize("scenario", ["office", "corridor-outage"])
def test_in_memory_run_equals_emulate_record_then_replay(scenario):
    estimates, pipe = run_in_memory(scenario, seed=2)
    assert [estimate_line(e) for e in estimates] == estimate_lines(scenario, 2)
    assert pipe.stats()["ports"]["nanoloc"]["frames"] > 0


def test_in_memory_run_takes_the_filters_and_duration_it_is_given():
    estimates, _ = run_in_memory("office", seed=1, filters=("wsn",), duration=5.0)
    assert estimates and {e.filter for e in estimates} == {"wsn"}
    assert max(e.t for e in estimates) < 5.5


def test_the_lab_registers_its_benchmarks():
    from navtwin.lab.bench import benchmarks

    assert {"host-latency", "host-replay", "lab-in-memory", "lab-soak", "lab-sweep"} <= set(benchmarks())


def test_replay_speeds_replays_each_filter_set_over_the_same_recording(capsys):
    """The replay benchmark's sets see the same bytes: the lines each gives are its
    tracks' output instants (5 s of office at 10 Hz per track; wsn from its first fix)."""
    import json

    from navtwin.cli.main import main
    from navtwin.lab.bench import office_replays

    r = office_replays(5.0, {"one": ("sins",), "two": ("sins", "kf")}, runs=2)
    assert r["one"]["filters"] == ["sins"] and r["two"]["filters"] == ["sins", "kf"]
    assert r["two"]["lines"] == 2 * r["one"]["lines"] > 40
    for res in r.values():
        lo, hi = res["wall_s_range"]
        assert res["runs"] == 2 and lo <= res["wall_s"] <= hi
        assert res["recorded_s"] == pytest.approx(5.0, abs=0.1)
    assert main(["bench", "host-replay", "--seconds", "5", "--runs", "1", "--filters", "wsn"]) == 0
    assert json.loads(capsys.readouterr().out)["filters"] == ["wsn"]
