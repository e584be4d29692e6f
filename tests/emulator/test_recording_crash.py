"""Emulator recordings that survive kill -9 and full disks (issue 7, points 4 and 5, and
"--record follows a symlink"): what a killed run leaves replays, and is the full run's
prefix; a write that fails ends the run with one line, exit 2 and a closed recording."""
import json
import subprocess
import time

import pytest

from navtwin.emulator import runner
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.cli.main import main
from navtwin.protocols.ports import names
from navtwin.protocols.recording import Recording
from ..fs_helpers import fsize_limit
from ..helpers import NAVTWIN

PORTS = names()  # the lab's ports, in its order
DEADLINE_S = 120.0


def golden(root):
    return root / "fixtures" / "golden" / "office"


def recorded_until_ns(d) -> int:
    """The device time of the last chunk whose index line is complete on disk, on every port."""
    until = []
    for port in PORTS:
        try:
            lines = (d / f"{port}.csv").read_bytes().split(b"\n")[1:-1]
        except FileNotFoundError:
            return -1
        until.append(int(lines[-1].split(b",")[2]) if lines else -1)
    return min(until)


def replay_lines(d) -> tuple[int, list[str], str]:
    res = subprocess.run([*NAVTWIN, "replay", str(d)], capture_output=True, timeout=DEADLINE_S)
    return res.returncode, res.stdout.decode().splitlines(), res.stderr.decode()


@pytest.mark.pty
def test_replay_of_an_emulator_killed_with_sigkill(root, tmp_path):
    gold = Recording(golden(root))
    d = tmp_path / "rec"
    proc = subprocess.Popen([*NAVTWIN, "emulate", "--scenario", "office", "--seed",
                             str(gold.meta["seed"]), "--duration", "10", "--speed", "5",
                             "--link-dir", str(tmp_path / "links"), "--record", str(d), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + DEADLINE_S
        while recorded_until_ns(d) < 3_000_000_000:  # the flushed files grow as it runs
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "the recording did not reach 3 s"
            time.sleep(0.02)
    finally:
        proc.kill()
        proc.communicate(timeout=DEADLINE_S)
    rec = Recording(d)
    assert not rec.complete
    for port in ("sins", "nanoloc"):  # the bytes of a run are a function of scenario and seed
        got = rec.read_bytes(port)
        assert got and gold.read_bytes(port).startswith(got), port
    assert gold.read_bytes("xbee").startswith(rec.read_bytes("xbee"))
    truth = (d / "truth.csv").read_bytes()
    assert truth.count(b"\n") > 1 and (golden(root) / "truth.csv").read_bytes().startswith(truth)

    code, lines, err = replay_lines(d)
    assert code == 0, err
    assert "is incomplete" in err.splitlines()[0] and "Traceback" not in err
    _, full, _ = replay_lines(golden(root))
    # estimates up to shortly before the cut are the full run's (later ones lack data)
    cut_s = recorded_until_ns(d) / 1e9 - 0.5
    prefix = [x for x in full if json.loads(x)["t"] < cut_s]
    assert len(prefix) > 100 and lines[:len(prefix)] == prefix


def test_emulate_record_on_a_full_filesystem_ends_with_one_line(tmp_path):
    d = tmp_path / "rec"
    res = subprocess.run([*NAVTWIN, "emulate", "--scenario", "office", "--duration", "60",
                          "--speed", "max", "--link-dir", str(tmp_path / "links"), "--record",
                          str(d), "--quiet"], capture_output=True, text=True, timeout=DEADLINE_S,
                         preexec_fn=fsize_limit(256 << 10))
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    line, = res.stderr.splitlines()
    assert line.startswith(f"navtwin emulate: error: --record {d}/") and "File too large" in line
    assert "ulimit -f" in line
    ready, done = map(json.loads, res.stdout.splitlines())
    assert done["done"] and "File too large" in done["recording_error"]
    rec = Recording(d)
    assert not rec.complete and "File too large" in rec.meta["write_error"]
    code, lines, err = replay_lines(d)
    assert code == 0 and lines and "is incomplete" in err, err


def test_emulate_record_on_a_full_tmpfs_ends_with_one_line(small_fs, tmp_path):
    d = small_fs / "rec"
    res = subprocess.run([*NAVTWIN, "emulate", "--scenario", "office", "--duration", "60",
                          "--speed", "max", "--link-dir", str(tmp_path / "links"), "--record",
                          str(d), "--quiet"], capture_output=True, text=True, timeout=DEADLINE_S)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    line, = res.stderr.splitlines()
    assert line.startswith(f"navtwin emulate: error: --record {d}/")
    assert "No space left on device; the filesystem is full" in line
    assert "No space left" in json.loads(res.stdout.splitlines()[-1])["recording_error"]
    assert not Recording(d).complete
    code, lines, err = replay_lines(d)
    assert code == 0 and lines and "is incomplete" in err, err


def test_emulate_refuses_to_record_through_a_symlink(capsys, tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    code = main(["emulate", "--scenario", "office", "--duration", "1", "--speed", "max",
                 "--link-dir", str(tmp_path / "links"), "--record", str(tmp_path / "link"),
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "is a symbolic link" in err and len(err.splitlines()) == 1, err
    assert not any(target.iterdir())


def test_truth_written_as_the_run_goes_equals_the_golden(root, tmp_path, monkeypatch):
    monkeypatch.setattr(runner, "FLUSH_NS", 0)  # flush at every step of the loop
    monkeypatch.setattr(runner, "TRUTH_STEP_NS", 7_777_777)  # rows made in odd pieces
    gold = Recording(golden(root))
    with Emulation(load_scenario("office"), gold.meta["seed"], speed=None, ports=False,
                   duration_s=gold.meta["duration_s"], record=tmp_path / "rec") as emu:
        emu.run()
    assert (tmp_path / "rec" / "truth.csv").read_bytes() == \
        (golden(root) / "truth.csv").read_bytes()
    assert Recording(tmp_path / "rec").complete
