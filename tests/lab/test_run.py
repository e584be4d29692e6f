"""The in-memory run gives exactly what recording the emulator and replaying it gives."""
import numpy as np
import pytest

from navtwin.emulator.imu import shared_truth
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.world import World
from navtwin.host.output import estimate_line
from navtwin.lab.run import run_in_memory, truth
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


def test_the_truth_is_the_worlds_every_seeds_and_made_once_in_a_task():
    sc = load_scenario("office")
    w = World(sc, 4)
    want = w.truth(0, w.duration_ns)
    got = truth(sc, 4)
    assert np.array_equal(got["t"], want["t"] / 1e9)
    assert all(np.array_equal(got[k], want[k]) for k in ("x", "y", "vx", "vy"))
    with shared_truth():
        one, two = truth(sc, 1), truth(sc, 2)
    assert one["x"] is two["x"] and not one["x"].flags.writeable
    assert one["x"].flags.c_contiguous  # np.interp takes it as it is, without a copy
    assert truth(sc, 1)["x"] is not one["x"]  # outside a task: made each time
    with pytest.raises(ValueError, match="vehicles 1..1"):
        truth(sc, 1, vehicle=2)
