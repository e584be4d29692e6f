"""``navtwin emulate``: the ready and done lines, links, signals, one-line errors."""
import json
import os
import select
import signal
import subprocess

import pytest

from ..helpers import NAVTWIN, navtwin, one_line_error

DEADLINE = 60.0


def test_help_lists_the_options():
    out = navtwin("emulate", "--help")
    assert out.returncode == 0
    for opt in ("--scenario", "--seed", "--duration", "--speed", "--link-dir", "--record",
                "--overwrite", "--quiet"):
        assert opt in out.stdout


@pytest.mark.parametrize("args,words", [
    (["--scenario", "nowhere"], ["nowhere"]),
    (["--scenario", "office", "--speed", "fast"], ["--speed", "realtime"]),
    (["--scenario", "office", "--speed", "-1"], ["--speed", "positive"]),
    (["--scenario", "office", "--duration", "1e6"], ["--duration", "office"]),
    (["--scenario", "office", "--seed", "x"], ["--seed"]),
    ([], ["--scenario"]),
])
def test_bad_arguments_get_one_line(tmp_path, args, words):
    one_line_error(navtwin("emulate", *args, "--link-dir", tmp_path / "l"), *words)
    assert not (tmp_path / "l").exists()  # nothing left behind


def test_bad_scenario_file_gets_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nduration_s = -5\n')
    one_line_error(navtwin("emulate", "--scenario", bad, "--link-dir", tmp_path / "l"),
                   "duration_s")


def test_unsafe_link_dir_gets_one_line(tmp_path):
    d = tmp_path / "open"
    d.mkdir()
    os.chmod(d, 0o777)
    one_line_error(navtwin("emulate", "--scenario", "office", "--link-dir", d), "chmod 700")


def test_record_into_a_non_empty_directory_needs_overwrite(tmp_path):
    d = tmp_path / "rec"
    d.mkdir()
    (d / "thesis.tex").write_text("precious")
    one_line_error(navtwin("emulate", "--scenario", "office", "--record", d, "--overwrite",
                           "--link-dir", tmp_path / "l"), "not a navtwin recording")
    (d / "recording.json").write_text("{}")
    one_line_error(navtwin("emulate", "--scenario", "office", "--record", d,
                           "--link-dir", tmp_path / "l"), "--overwrite")
    assert (d / "thesis.tex").read_text() == "precious"


@pytest.mark.pty
def test_unwritable_record_directory_gets_one_line(tmp_path):
    (tmp_path / "file").write_text("")
    one_line_error(navtwin("emulate", "--scenario", "office", "--record", tmp_path / "file" / "rec",
                           "--link-dir", tmp_path / "l"), "--record", "writ")
    assert not (tmp_path / "l").exists()


@pytest.mark.pty
def test_virtual_run_prints_ready_then_done_and_cleans_up(tmp_path):
    links = tmp_path / "links"
    out = navtwin("emulate", "--scenario", "corridor", "--seed", 3, "--duration", 5,
                  "--speed", "max", "--link-dir", links, "--record", tmp_path / "rec")
    assert out.returncode == 0, out.stderr
    ready, done = (json.loads(line) for line in out.stdout.splitlines())
    assert ready["ready"] is True
    assert ready["ports"] == {p: str(links / p) for p in ("sins", "xbee", "nanoloc")}
    assert all(pts.startswith("/dev/pts/") for pts in ready["pts"].values())
    assert (ready["scenario"], ready["seed"], ready["speed"], ready["link_dir"]) == \
        ("corridor", 3, "max", str(links))
    assert done["done"] is True and not done["interrupted"] and done["virtual_s"] == 5.0
    assert done["ports"]["sins"]["frames"] == 500
    assert done["ports"]["sins"]["dropped_unplugged"] == done["ports"]["sins"]["bytes"] == 15000
    assert not links.exists()  # links removed, and the directory it created too
    assert (tmp_path / "rec" / "truth.csv").is_file()


def _start(*args):
    proc = subprocess.Popen([*NAVTWIN, "emulate", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert select.select([proc.stdout], [], [], DEADLINE)[0]
    return proc, json.loads(proc.stdout.readline())


@pytest.mark.pty
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_cleanly_with_a_summary(tmp_path, sig):
    proc, ready = _start("--scenario", "office", "--link-dir", tmp_path / "l", "--quiet")
    try:
        links = [ready["ports"][p] for p in ("sins", "xbee", "nanoloc")]
        assert all(os.path.realpath(link) == ready["pts"][p]
                   for link, p in zip(links, ("sins", "xbee", "nanoloc")))
        with open(links[0], "rb", buffering=0) as port:  # running: bytes flow
            assert select.select([port], [], [], DEADLINE)[0] and port.read(30)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=DEADLINE)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    (done,) = (json.loads(line) for line in out.splitlines())
    assert done["done"] and done["interrupted"] and done["ports"]["sins"]["attaches"] == 1
    assert not any(os.path.lexists(link) for link in links)


@pytest.mark.pty
def test_progress_goes_to_stderr_and_stdout_stays_clean(tmp_path):
    proc, ready = _start("--scenario", "office", "--speed", "2", "--link-dir", tmp_path / "l")
    try:
        assert select.select([proc.stderr], [], [], DEADLINE)[0]
        line = proc.stderr.readline()
        assert line.startswith("office: ") and "x real time" in line
        proc.terminate()
        out, _ = proc.communicate(timeout=DEADLINE)
    finally:
        proc.kill()
    assert [json.loads(line)["done"] for line in out.splitlines()] == [True]


@pytest.mark.pty
def test_second_emulator_on_the_same_link_dir_is_refused(tmp_path):
    proc, ready = _start("--scenario", "office", "--link-dir", tmp_path / "l", "--quiet")
    try:
        line = one_line_error(navtwin("emulate", "--scenario", "office", "--link-dir",
                                      tmp_path / "l"), "in use")
        assert f"pid {proc.pid}" in line
        assert os.path.realpath(ready["ports"]["xbee"]) == ready["pts"]["xbee"]  # untouched
    finally:
        proc.terminate()
        proc.communicate(timeout=DEADLINE)
