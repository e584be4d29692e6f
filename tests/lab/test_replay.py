"""Replay: a host recording gives the pipeline's estimates exactly; emulator recordings
get synthesised arrival times."""
import dataclasses
import json
import shutil

import pytest

from navtwin.host import config as host_config
from navtwin.host.bench import write_host_recording
from navtwin.host.output import estimate_line
from navtwin.host.pipeline import Pipeline
from navtwin.host.replay import chunks, replay, settings
from navtwin.host.tracks import BUILT_IN
from navtwin.protocols import sins
from navtwin.protocols.recording import Recording, RecordingWriter
from navtwin.protocols.serial import wire_ns

from ..helpers import OFFICE, navtwin, tight
from ..host.fake_estimator import RecordingEstimator
from . import lab_bytes



def direct_lines(chunks_, filters=BUILT_IN, config=OFFICE) -> str:
    pipe = Pipeline(config, filters)
    out = []
    for c in chunks_:
        out += pipe.feed(*c)
    out += pipe.finish()
    return "".join(map(estimate_line, out))


@pytest.fixture(scope="module")
def host_recording(tmp_path_factory):
    data = list(lab_bytes.office(8.0, 11))
    path = write_host_recording(tmp_path_factory.mktemp("rec") / "run", OFFICE,
                                BUILT_IN, data)
    return path, data


def test_replay_of_a_host_recording_equals_the_pipeline_run(host_recording):
    path, data = host_recording
    expected = direct_lines(data)
    got = []
    replay(Recording(path), lambda es: got.extend(map(estimate_line, es)))
    assert "".join(got) == expected
    filters = {json.loads(line)["filter"] for line in expected.splitlines()}
    assert filters == set(BUILT_IN)


def test_navtwin_replay_prints_the_same_bytes(host_recording, tmp_path):
    path, data = host_recording
    expected = direct_lines(data)
    res = navtwin("replay", path)
    assert res.returncode == 0, res.stderr
    assert res.stdout == expected
    summary = json.loads(res.stderr.strip().splitlines()[-1])["summary"]
    assert summary["counts"]["imu"] == 800
    out = tmp_path / "est.jsonl"
    res = navtwin("replay", path, "--out", out, "--filters", "wsn,ukf")
    assert res.returncode == 0, res.stderr
    assert {json.loads(x)["filter"] for x in out.read_text().splitlines()} == {"wsn", "ukf"}


def test_recorded_config_is_used_unless_overridden(host_recording):
    path, _ = host_recording
    rec = Recording(path)
    assert settings(rec)["config"] == OFFICE
    corridor = host_config.load("corridor")
    assert settings(rec, config=corridor)["config"] == corridor


def test_a_recording_with_tight_shared_in_filters_replays_as_it_ran(host_recording, tmp_path):
    """Host recordings made before issue 18 hold ``tight`` in the config's [filters], the EKF's
    and UKF's range measurement at once: they replay as the config with it in both tracks'
    own sections (and not as the default TDOA)."""
    path, data = host_recording
    old = tmp_path / "rec"
    shutil.copytree(path, old)
    meta = json.loads((old / "recording.json").read_text())
    meta["host"]["config"]["filters"]["tight"] = "toa"
    (old / "recording.json").write_text(json.dumps(meta))
    got = []
    replay(Recording(old), lambda es: got.extend(map(estimate_line, es)))
    toa = direct_lines(data, config=dataclasses.replace(OFFICE, settings=tight("toa")))
    assert "".join(got) == toa != direct_lines(data)


def _emulator_recording(path, chunks_by_port):
    meta = {"source": "navtwin emulate", "scenario": "office", "seed": 1,
            "ports": {"sins": {"baud": 115200}, "xbee": {"baud": 115200, "api_mode": 2},
                      "nanoloc": {"baud": 115200}}}
    with RecordingWriter(path, meta) as rec:
        for port, items in chunks_by_port.items():
            for t_dev, data in items:
                rec.port(port).write(data, t_device_ns=t_dev)
    return Recording(path)


def test_emulator_recording_arrival_is_last_byte_off_the_uart(tmp_path):
    frame = sins.build_sample(0, [0x8000] * 11)
    rec = _emulator_recording(tmp_path / "emu", {
        "sins": [(0, frame)],
        "xbee": [(1_000_000, b"\x7e" * 10)],
        "nanoloc": [(1_000_004, b"N" * 10), (5_000_000, b"L")]})
    kw = settings(rec)
    assert kw["inputs"] == ("xbee", "nanoloc") and kw["escaped"] is True
    assert kw["config"].name == "office"
    got = list(chunks(rec, kw["inputs"]))
    # a byte is 10 bits at 115200 baud = 86 805.6 ns; 10 bytes 868 055.6 ns
    assert [(p, t) for p, _, t in got] == [("xbee", 1_868_056), ("nanoloc", 1_868_060),
                                           ("nanoloc", 5_086_806)]


def test_emulator_recording_ties_are_made_strictly_increasing(tmp_path):
    rec = _emulator_recording(tmp_path / "emu", {"xbee": [(0, b"\x7e")], "nanoloc": [(0, b"N")]})
    got = [(p, t) for p, _, t in chunks(rec, ("xbee", "nanoloc"))]
    assert got == [("xbee", 86_806), ("nanoloc", 86_807)]


def test_replay_runs_an_emulator_recording_through_the_pipeline(tmp_path):
    data = list(lab_bytes.office(2.0, 12))
    # as the emulator would record it: device time = first byte out = last byte - wire time
    by_port: dict = {}
    for port, chunk, t in data:
        by_port.setdefault(port, []).append((t - wire_ns(len(chunk), 115200), chunk))
    rec = _emulator_recording(tmp_path / "emu", by_port)
    est = RecordingEstimator()
    replay(rec, lambda es: None, make_estimator=lambda _: est)
    assert sum(c[0] == "imu" for c in est.calls) == 200
    assert sum(c[0] == "range" for c in est.calls) == 80


def _broken_copy(host_recording, tmp_path, unknown_filter=False, untimed=slice(0, 0)):
    """A copy of the host recording whose meta names an unknown filter, or whose xbee index
    has no arrival time on the lines *untimed*."""
    d = tmp_path / "rec"
    shutil.copytree(host_recording[0], d)
    if unknown_filter:
        meta = json.loads((d / "recording.json").read_text())
        meta["host"]["filters"].append("nope")
        (d / "recording.json").write_text(json.dumps(meta))
    head, *lines = (d / "xbee.csv").read_text().splitlines()
    col = head.split(",").index("t_wall_ns")

    def untime(line: str) -> str:
        cells = line.split(",")
        cells[col] = ""
        return ",".join(cells)

    lines[untimed] = [untime(line) for line in lines[untimed]]
    (d / "xbee.csv").write_text("\n".join([head, *lines]) + "\n")
    return d


@pytest.mark.parametrize("case, words", [
    ({"unknown_filter": True}, ["recording.json: the recorded filters", "'nope'", "--filters"]),
    ({"untimed": slice(None)}, ["port 'xbee' chunk at offset 0", "t_wall_ns"]),
    ({"untimed": slice(5, 6)}, ["port 'xbee' chunk at offset", "t_wall_ns"])])
def test_a_host_recording_it_cannot_replay_is_one_line_and_exit_2(host_recording, tmp_path,
                                                                 capsys, case, words):
    from navtwin.cli.main import main

    d = _broken_copy(host_recording, tmp_path, **case)
    out = tmp_path / "mine.jsonl"
    out.write_text("the user's lines\n")
    argv = ["replay", str(d)] + (["--out", str(out)] if "unknown_filter" in case
                                 or case["untimed"] == slice(None) else [])
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert out.read_text() == "the user's lines\n"  # refused before --out was opened
