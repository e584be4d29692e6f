"""Several recordings replayed at once: each into its own file, the lines `navtwin replay DIR`
gives, the same with any number of jobs; bad input is one line and writes nothing."""
from __future__ import annotations

import json

import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario

from ..helpers import navtwin


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("recs")
    sc = load_scenario("office")
    for seed in (1, 2, 3):
        with Emulation(sc, seed, speed=None, ports=False, duration_s=20, record=root / f"s{seed}") as emu:
            emu.run()
    return root


def test_each_recording_gets_the_lines_of_its_own_replay_whatever_the_jobs(recordings, tmp_path):
    dirs = [recordings / f"s{s}" for s in (1, 2, 3)]
    alone = {d.name: navtwin("replay", d, "--filters", "kf,wsn").stdout for d in dirs}
    for jobs in (1, 2):
        out = tmp_path / f"j{jobs}"
        p = navtwin("replay", *dirs, "--out-dir", out, "--jobs", jobs, "--filters", "kf,wsn")
        assert p.returncode == 0, p.stderr
        for d in dirs:
            assert (out / f"{d.name}.jsonl").read_text() == alone[d.name] != ""
        lines = [json.loads(x) for x in p.stderr.splitlines()]
        assert [x["summary"]["recording"] for x in lines[:-1]] == [str(d) for d in dirs]
        assert all(x["summary"]["cpu_s"] > 0 for x in lines[:-1])
        assert lines[-1]["replays"] == {**lines[-1]["replays"], "recordings": 3, "jobs": jobs}


@pytest.mark.parametrize("extra, message", [
    ((), "several recordings need --out-dir OUT"),
    (("--out-dir", "{o}", "--out", "x.jsonl"), "leave --out out"),
    (("{r}/nowhere", "--out-dir", "{o}"), "nowhere: no recording.json"),
    (("{r}/s1", "--out-dir", "{o}"), "would both write"),
    (("--out-dir", "{o}", "--config", "nowhere"), "no host config named 'nowhere'"),
])
def test_bad_replays_are_one_line_and_write_nothing(recordings, tmp_path, extra, message):
    o = tmp_path / "out"
    args = [a.format(o=o, r=recordings) for a in extra]
    p = navtwin("replay", recordings / "s1", recordings / "s2", *args)
    assert p.returncode == 2 and message in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not o.exists()


def test_jobs_with_one_recording_is_one_line(recordings):
    p = navtwin("replay", recordings / "s1", "--jobs", "2")
    assert p.returncode == 2 and "give several DIRs and --out-dir" in p.stderr
