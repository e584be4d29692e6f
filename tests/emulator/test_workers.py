"""Worker processes (emulator.workers): a vehicle's bytes are the same whichever process
hosts it; one ready and one done line; the refusals; a worker that dies ends the run."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import defaultdict

import pytest

from navtwin.emulator.fleet import convoy
from navtwin.emulator.runner import Emulation, RunError
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.workers import Workers, auto, refusal


def run_bytes(sc, vehicles=None):
    streams, air = defaultdict(bytearray), []

    def sink(chunk):
        streams[chunk.port] += chunk.data

    with Emulation(sc, 7, speed=None, duration_s=3, ports=False, sink=sink,
                   air_sink=lambda f: air.append((f.t_ns, f.psdu)), vehicles=vehicles) as emu:
        emu.run()
    return dict(streams), air


def test_each_worker_gives_its_vehicles_the_bytes_of_the_single_process_run():
    sc = convoy(load_scenario("office"), 4, network="per-vehicle")
    whole, whole_air = run_bytes(sc)
    odd, odd_air = run_bytes(sc, (1, 3))  # worker 1 of 2
    even, even_air = run_bytes(sc, (2, 4))  # worker 2 of 2
    assert set(odd) == {"sins", "xbee", "nanoloc", "sins3", "xbee3", "nanoloc3"}
    assert {**odd, **even} == whole and all(whole.values())
    assert sorted(odd_air + even_air) == sorted(whole_air)


def emulate(tmp_path, *args, check=True):
    return subprocess.run([sys.executable, "-m", "navtwin", "emulate", "--scenario", "office",
                           "--quiet", "--link-dir", str(tmp_path / "links"), *args],
                          capture_output=True, text=True, timeout=180, check=check)


def test_two_workers_give_one_ready_and_one_done_line_with_every_port(tmp_path):
    fleet = ["--vehicles", "4", "--network", "per-vehicle", "--speed", "max", "--duration", "2"]
    out = emulate(tmp_path, *fleet, "--workers", "2")
    ready, done = (json.loads(line) for line in out.stdout.splitlines())
    sc = convoy(load_scenario("office"), 4, network="per-vehicle")
    assert list(ready["ports"]) == [name for name, _ in sc.instances()] == list(done["ports"])
    assert ready["workers"] == 2 and ready["vehicles_per_worker"] == [[1, 3], [2, 4]]
    assert ready["control"] is None and not (tmp_path / "links").exists()  # links removed
    alone = json.loads(emulate(tmp_path, *fleet).stdout.splitlines()[1])
    for name, entry in alone["ports"].items():
        assert (done["ports"][name]["frames"], done["ports"][name]["bytes"]) == \
            (entry["frames"], entry["bytes"])


@pytest.mark.parametrize("args, message", [
    (["--vehicles", "4", "--workers", "2"], "pass --network per-vehicle"),
    (["--vehicles", "2", "--network", "per-vehicle", "--workers", "2", "--record", "r"],
     "--record needs the one loop"),
])
def test_what_workers_cannot_do_is_refused_in_one_line(tmp_path, args, message):
    out = emulate(tmp_path, *args, check=False)
    assert out.returncode == 2 and out.stdout == ""
    (line,) = out.stderr.splitlines()
    assert message in line


def test_auto_is_one_worker_at_max_speed_and_when_vehicles_share_the_air():
    sc = convoy(load_scenario("office"), 4, network="per-vehicle")
    assert auto(sc, 7, None) == 1
    assert auto(convoy(load_scenario("office"), 4), 7, 1.0) == 1
    assert 1 <= auto(sc, 7, 1.0) <= min(4, os.cpu_count())
    assert refusal(sc, 2) is None and refusal(convoy(load_scenario("office"), 2), 2)


def _two_workers(tmp_path, stderr) -> subprocess.Popen:
    """`navtwin emulate` of two office cars on two workers, for a minute."""
    return subprocess.Popen([sys.executable, "-m", "navtwin", "emulate", "--scenario", "office",
                             "--quiet", "--link-dir", str(tmp_path / "links"), "--vehicles", "2",
                             "--network", "per-vehicle", "--workers", "2", "--duration", "60"],
                            stdout=subprocess.PIPE, stderr=stderr, text=True)


@pytest.mark.pty
def test_a_worker_that_dies_ends_the_run_with_one_line(tmp_path):
    proc = _two_workers(tmp_path, subprocess.PIPE)
    ready = json.loads(proc.stdout.readline())
    os.kill(ready["worker_pids"][1], signal.SIGKILL)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and out == ""
    (line,) = err.splitlines()
    assert "worker 2 (vehicles 2) ended with status -9" in line
    assert not (tmp_path / "links").exists()


@pytest.mark.pty
def test_workers_end_when_their_parent_is_killed(tmp_path):
    proc = _two_workers(tmp_path, subprocess.DEVNULL)
    ready = json.loads(proc.stdout.readline())
    proc.kill()
    proc.wait()
    for pid in ready["worker_pids"]:  # orphans now: ours to reap is not possible; poll /proc
        deadline = time.monotonic() + 30
        while os.path.exists(f"/proc/{pid}") and _state(pid) != "Z" and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not os.path.exists(f"/proc/{pid}") or _state(pid) == "Z"


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


def test_a_subset_needs_its_own_networks():
    with pytest.raises(RunError, match="per-vehicle"):
        Workers(convoy(load_scenario("office"), 2), 7, 2, speed=None, duration_s=1)
