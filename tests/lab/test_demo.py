"""`navtwin demo` and the live errors it draws: truth and estimates tailed from the files
both sides write, equal to the after-the-run figures."""
import json
import re
import threading

import numpy as np
import pytest

from navtwin.emulator.truth import HEADER, csv_rows
from navtwin.emulator.world import World
from navtwin.host import tracks
from navtwin.host.output import estimate_line
from navtwin.lab import evaluate
from navtwin.lab.live import LiveErrors, Tail
from navtwin.lab.orchestrator import PHASES, Watch, _watch
from navtwin.lab.fleet import followers
from navtwin.host import config as host_config
from navtwin.lab.run import run_in_memory
from navtwin.emulator.scenario import load_scenario

from ..helpers import navtwin


def test_a_tail_yields_whole_lines_only_and_each_once(tmp_path):
    p = tmp_path / "f"
    tail = Tail(p)
    assert tail.lines() == []  # not there yet
    p.write_bytes(b"a\nb")
    assert tail.lines() == ["a"]
    with open(p, "ab") as f:
        f.write(b"c\n\nd\n")
    assert tail.lines() == ["bc", "d"] and tail.lines() == []


def test_live_errors_on_growing_files_equal_the_errors_after_the_run(tmp_path):
    sc = load_scenario("office")
    estimates, _ = run_in_memory(sc, 1, duration=12)
    w = World(sc, 1)
    tr = w.truth(0, 12 * 10**9)
    truth_csv, est_file = tmp_path / "truth.csv", tmp_path / "estimates.jsonl"
    truth_bytes = HEADER + csv_rows(tr)
    lines = "".join(map(estimate_line, estimates)).encode()
    live = LiveErrors(truth_csv, est_file)
    # both files grow in uneven pieces, cut mid-line, the truth ahead or behind
    cuts_t = np.linspace(0, len(truth_bytes), 23).astype(int)
    cuts_e = np.linspace(0, len(lines), 17).astype(int)
    for k in range(1, 24):
        truth_csv.write_bytes(truth_bytes[:cuts_t[k - 1]] if k % 3 else truth_bytes[:cuts_t[k]])
        est_file.write_bytes(lines[:cuts_e[min(k, 16)]])
        live.update(None if k < 4 else 0.0)  # the offset is known late: estimates wait
    truth_csv.write_bytes(truth_bytes)
    est_file.write_bytes(lines)
    got = live.update(0.0)
    truth = evaluate.load_truth(truth_csv)  # the file's rounding, as after a run
    want = {}
    for name, e in evaluate.load_estimates(lines.decode().splitlines()).items():
        keep = e["t"] <= truth["t"][-1]
        want[name] = evaluate.error(truth, e)[keep]
    assert set(got) == set(want) == {"sins", "wsn", "kf", "ekf", "ukf"}
    for name, err in want.items():
        g = got[name]
        assert g.n == err.size and g.max == err.max() and g.last == err[-1]
        assert g.mean == pytest.approx(err.mean(), rel=1e-12)


def test_a_host_heard_only_after_the_run_ended_is_still_scored_live(tmp_path):
    # a starved host may send its first status line once the emulator has gone: the tick
    # then still shows each track's error (the clocks' offset known from an earlier status)
    sc = load_scenario("office")
    estimates, _ = run_in_memory(sc, 1, duration=4)
    (tmp_path / "emulator").mkdir()
    (tmp_path / "emulator" / "truth.csv").write_bytes(
        HEADER + csv_rows(World(sc, 1).truth(0, 4 * 10**9)))
    (tmp_path / "estimates.jsonl").write_text("".join(map(estimate_line, estimates)))
    log, t0 = tmp_path / "host.log", 123 * 10**9

    class Lab:  # a status while it runs, then gone (its control socket closed)
        ticks = 0

        def running(self):
            return self.ticks < 2

        def status(self):
            self.ticks += 1
            if self.ticks > 1:
                raise OSError("the emulator has stopped")
            return {"t0_monotonic_ns": t0, "virtual_s": 1.0}

    class Host:
        def poll(self):
            return None

    seen = []

    class Seen(Watch):
        tick_s = 0.01

        def tick(self, state):
            seen.append({**state, "tracks": dict(state["tracks"])})  # its dict grows
            log.write_text(json.dumps({"status": {"t0_monotonic_ns": t0, "t_s": 4.0}}) + "\n")

    log.write_text("")
    _watch(Lab(), [Host()], followers(sc, host_config.load("office")), tmp_path, Seen(), threading.Event())
    assert [s["emulator"] is None for s in seen] == [False, True]
    assert not seen[0]["tracks"] and seen[1]["host"]
    assert set(seen[1]["tracks"]) == {"sins", "wsn", "kf", "ekf", "ukf"}


@pytest.mark.pty
@pytest.mark.slow
def test_demo_runs_every_track_and_ends_with_the_table_and_the_run_directory(tmp_path):
    d = tmp_path / "run"
    # long enough that a host slow to start on a loaded box (all tracks: 9 s seen at load 6)
    # still sends status lines before the run ends
    p = navtwin("demo", "--duration", "15", "--dir", d, timeout=180)
    assert p.returncode == 0, p.stderr[-2000:]
    out, err = p.stdout, p.stderr
    report = json.loads((d / "report.json").read_text())
    assert set(report["errors"]) == set(tracks.names())  # every track
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if line.strip()}
    for name, e in report["errors"].items():  # the table on stdout is the report's
        assert rows[name][:2] == [f"{e['mean']:.3f}", f"{e['max']:.3f}"]
    assert str(d) in out
    # stdout is not a terminal: plain progress lines there, in order, before the table
    lines = out.splitlines()
    assert lines[:2] == [PHASES["starting"], f"running office (seed {report['emulator']['seed']})"
                         f" for 15 s in real time; run directory {d}"], out[:2000]
    ticks = [line for line in lines if re.match(r" *[\d.]+ (/ 15 s|s of wall time)", line)]
    # a host slow to start on a loaded machine may miss the first ticks, not every one
    live = [line for line in ticks if "error now (m)" in line]
    assert live and "ports xbee " in live[-1] and "nanoloc " in live[-1], out[:3000]
    assert all(f"{name} " in live[-1].split("error now (m)")[1] for name in report["errors"])
    end = lines.index(PHASES["ended"])
    assert lines.index(ticks[-1]) < end < lines.index(PHASES["reporting"]) < lines.index(
        next(line for line in lines if line.startswith("filter")))
    assert "\x1b[" not in out and "━" not in err  # no terminal drawing in a log
