"""docs/tutorial.md's steps, run as a newcomer runs them, and compared by shape with what the
page shows: the keys of each JSON line it prints, a table's columns and rows, the line that
says a run passed. Never exact floats or counts, which move with timing. Steps 2 to 5 and 7
run here (2 and 4-5 on their own link directory, 4-5 shortened); step 1 is ``navtwin demo``
(tests/lab/test_demo.py), step 3 the digi-xbee script and step 6 the example tests
(tests/test_docs.py)."""
from __future__ import annotations

import json
import re
import shlex
import signal
import subprocess
import time
from pathlib import Path

import pytest

from .helpers import DEADLINE_S, NAVTWIN, ROOT, navtwin

FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)


def blocks() -> list[tuple[str, str]]:
    return FENCE.findall((ROOT / "docs" / "tutorial.md").read_text(encoding="utf-8"))


def shown(command: str, nth: int = 0) -> list[str]:
    """The output lines the tutorial shows under the *nth* of its console commands that
    start with *command*."""
    found = []
    for lang, body in blocks():
        if lang != "console":
            continue
        for line in body.splitlines():
            if line.startswith("$ "):
                found.append([] if line[2:].startswith(command) else None)
            elif found and found[-1] is not None:
                found[-1].append(line)
    found = [x for x in found if x is not None]
    assert len(found) > nth, f"docs/tutorial.md shows no '$ {command}' (#{nth + 1})"
    return found[nth]


def doc_keys(line: str) -> set[str]:
    """The keys a (trimmed, so not parseable) JSON line of the page names, at any depth,
    but for the error kinds counted, which are what that run met."""
    return set(re.findall(r'"(\w+)":', re.sub(r'"(errors|error_bytes)":\{[^{}]*\}', "", line)))


def keys(value) -> set[str]:
    """Every key of a parsed JSON value, at any depth."""
    if isinstance(value, dict):
        return set(value).union(*(keys(v) for v in value.values()))
    if isinstance(value, list):
        return set().union(*(keys(v) for v in value))
    return set()


def assert_shape(doc_line: str, line: str) -> dict:
    """*line* (real output) parses and has every key *doc_line* shows; the page's line has
    every top-level key of the real one when it is not trimmed."""
    value = json.loads(line)
    missing = doc_keys(doc_line) - keys(value)
    assert not missing, f"the tutorial shows {sorted(missing)}, which today's output lacks: {line}"
    if "…" not in doc_line:
        assert set(value) == set(json.loads(doc_line)), (doc_line, line)
    return value


def read_until(stream, enough, what: str) -> list[str]:
    """Lines of *stream* until ``enough(lines)`` holds; fails at the deadline."""
    lines: list[str] = []
    end = time.monotonic() + DEADLINE_S
    while not enough(lines):
        assert time.monotonic() < end, f"{what}: only {lines[-3:]} after {DEADLINE_S:g} s"
        line = stream.readline()
        assert line, f"{what} ended: {lines[-3:]}"
        lines.append(line.rstrip("\n"))
    return lines


class Emulator:
    """``navtwin emulate ARGS --link-dir DIR`` until its ready line; stopped at exit."""

    def __init__(self, args: list[str], link_dir: Path, cwd: Path | None = None) -> None:
        self.proc = subprocess.Popen([*NAVTWIN, "emulate", *args, "--link-dir", str(link_dir)],
                                     cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True)
        self.ready = read_until(self.proc.stdout, lambda x: x, "navtwin emulate")[0]

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        self.proc.communicate(timeout=DEADLINE_S)


@pytest.mark.pty
def test_step2_the_lab_lasts_the_step_and_decode_prints_what_the_page_shows(tmp_path):
    start = next(c for c in map(str.strip, _commands()) if c.startswith("navtwin emulate")
                 and "--record" not in c and "--duration" not in c)
    args = shlex.split(start)[2:]
    links = tmp_path / "links"
    with Emulator(args, links, ROOT) as lab:
        ready = assert_shape(shown(start)[0], lab.ready)
        # the step's lab outlasts its commands (a newcomer types for minutes: the office
        # scenario alone is 70 s, over before the decode commands)
        assert ready["duration_s"] >= 300, ready
        again = navtwin("emulate", *args, "--link-dir", str(links), cwd=ROOT)
        assert again.returncode == 2 and again.stdout == ""
        doc_error = shown(start, 1)[0]
        assert re.sub(r"/\S+|\d+", "#", again.stderr.strip()) == re.sub(r"/\S+|\d+", "#",
                                                                        doc_error)
        for fmt, port in (("sins", "sins"), ("xbee-sins", "xbee"), ("nanoloc", "nanoloc")):
            page = [x for x in shown(f"navtwin decode --format {fmt} --follow") if x != "…"]
            p = subprocess.Popen([*NAVTWIN, "decode", "--format", fmt, "--follow",
                                  ready["ports"][port]], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
            frames = read_until(p.stdout, lambda x: len(x) >= 20, f"decode {fmt}")
            p.send_signal(signal.SIGINT)  # Ctrl-C: the summary
            rest, err = p.communicate(timeout=DEADLINE_S)
            assert p.returncode == 0, err
            lines = frames + rest.splitlines()
            assert_shape(page[-1], lines[-1])  # the summary
            for doc_line, line in zip(page[:-1], lines[:2]):
                record = assert_shape(doc_line, line)
            # engineering units to the sensor's resolution: 0.87912, not 0.8791200000000001
            for value in (record.get("gyro_dps", []) + [record.get("distance_m") or 0.0]):
                assert len(repr(value).split(".")[-1]) <= 6, record


def _commands() -> list[str]:
    return [line[2:] for _, body in blocks() for line in body.splitlines()
            if line.startswith("$ ")]


@pytest.mark.pty
@pytest.mark.slow
def test_steps4_and_5_record_replay_break_and_audit(tmp_path):
    """Step 4's and 5's commands on one lab, shortened: once the host is back on the replugged
    port, it and then the lab are stopped as with Ctrl-C."""
    links, cwd = tmp_path / "links", tmp_path
    (cwd / "run").mkdir()
    with Emulator(["--scenario", "office", "--duration", "60", "--record", "run/emulator"],
                  links, cwd) as lab:
        ready = json.loads(lab.ready)
        host = subprocess.Popen(
            [*NAVTWIN, "host", "--xbee", ready["ports"]["xbee"], "--nanoloc",
             ready["ports"]["nanoloc"], "--record", "run/host", "--out", "live.jsonl",
             "--duration", "45"], cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            text=True)
        status = read_until(host.stderr, lambda x: any('"t_s"' in y for y in x), "host")
        ctl = ["ctl", "--link-dir", str(links)]
        replies = {}
        for command in ("status", "fault anchor_outage:anchor=1 --duration 2",
                        "fault bit_errors:port=xbee,ber=1e-4 --duration 5", "unplug xbee",
                        "replug xbee"):
            p = navtwin(*ctl, *command.split())
            assert p.returncode == 0, p.stderr
            replies[command] = assert_shape(shown(f"navtwin ctl {command}")[0], p.stdout)
            if command == "unplug xbee":  # the host sees the cable go before it comes back
                status += read_until(host.stderr, lambda x: any("port_down" in y for y in x),
                                     "host")
        status += read_until(host.stderr, lambda x: any("port_up" in y for y in x), "host")
        host.send_signal(signal.SIGINT)
        _, rest = host.communicate(timeout=DEADLINE_S)
        assert host.returncode == 0
    assert replies["replug xbee"]["plugged"] and replies["status"]["ok"]
    page = shown("navtwin host --xbee /tmp/navtwin-0/xbee --nanoloc /tmp/navtwin-0/nanoloc "
                 "--record run/host")
    lines = status + rest.splitlines()
    for doc_line, tags in zip(page, (['"event":"started"'], ['"t_s"', '"p50_ms"'])):
        assert_shape(doc_line, next(x for x in lines if all(tag in x for tag in tags)))
    assert_shape(page[-1], lines[-1])
    assert_shape(shown("head -1 live.jsonl")[0], (cwd / "live.jsonl").read_text().splitlines()[0])
    assert navtwin("replay", "run/host", "--out", "replay.jsonl", cwd=cwd).returncode == 0
    assert (cwd / "replay.jsonl").read_bytes() == (cwd / "live.jsonl").read_bytes()
    # step 5's audit: the page's columns, one row per port, and the verdict
    audit = navtwin("audit", "run/emulator", "run/host", cwd=cwd)
    assert audit.returncode == 0, audit.stdout + audit.stderr
    doc, got = shown("navtwin audit"), audit.stdout.splitlines()
    assert got[0].split() == doc[0].split()
    assert [x.split()[0] for x in got[1:3]] == [x.split()[0] for x in doc[1:3]]
    assert all(len(x.split()) == len(doc[0].split()) for x in got[1:3])
    # then a line per port with unseen bytes, by the cause the host saw, as on the page
    unseen = [x for x in got[3:] if x.startswith("unseen ")]
    assert [x.split(":")[0] for x in unseen] == [x.split(":")[0] for x in doc[3:3 + len(unseen)]]
    rest = got[3 + len(unseen):]
    assert re.fullmatch(r"ledger: \d+ entries", rest[0]) and got[-1] == doc[-1]


def test_step4_ten_seconds_at_full_speed_are_the_golden_recording(tmp_path):
    p = navtwin("emulate", "--scenario", "office", "--speed", "max", "--duration", "10",
                "--record", str(tmp_path / "rec"), "--quiet", "--link-dir", str(tmp_path / "l"))
    assert p.returncode == 0, p.stderr
    page = shown("navtwin emulate --scenario office --speed max")
    for doc_line, line in zip(page[:2], p.stdout.splitlines()):
        assert_shape(doc_line, line)
    for port in ("sins", "xbee", "nanoloc"):
        assert (tmp_path / "rec" / f"{port}.bin").read_bytes() == \
            (ROOT / "fixtures" / "golden" / "office" / f"{port}.bin").read_bytes()


@pytest.mark.slow
def test_step7_the_sweep_prints_the_pages_table(tmp_path):
    pytest.importorskip("distributed")
    pytest.importorskip("pyarrow")
    i, command = next((i, body) for i, (lang, body) in enumerate(blocks())
                      if body.startswith("navtwin sweep"))
    argv = shlex.split(command)[1:]
    argv[argv.index("--out") + 1] = str(tmp_path / "sw")
    p = navtwin(*argv, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    doc = [x for x in blocks()[i + 1][1].splitlines() if not x.startswith("seeds ")]
    got = p.stdout.splitlines()
    assert len(got) == len(doc), p.stdout
    for d, g in zip(doc, got):
        if d.startswith(("filter", "ranking")):
            assert g.split()[:1] == d.split()[:1] and len(g.split()) == len(d.split()), (d, g)
        elif d.strip():
            assert g.split()[0] == d.split()[0] and len(g.split()) == len(d.split()), (d, g)
        else:
            assert not g.strip()
