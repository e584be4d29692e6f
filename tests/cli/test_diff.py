"""`navtwin diff` end to end: recordings and byte files, exit 0 / 1 / 2 like diff, --json."""
import json
import re
import subprocess
import sys

import pytest

from navtwin.protocols import sins

from .. import recorded
from ..helpers import ROOT, navtwin, one_line_error


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return recorded.compared_runs(tmp_path_factory.mktemp("runs"))


def test_same_seed_exits_0(runs):
    p = navtwin("diff", runs["one"], runs["again"])
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[-1] == "equal"
    assert "sins (sins): equal; frames A 200 B 200" in p.stdout


def test_two_seeds_exit_1_with_the_first_frame_and_field(runs):
    p = navtwin("diff", runs["one"], runs["two"], "--port", "sins", "--max", 1)
    assert p.returncode == 1, p.stderr
    lines = p.stdout.splitlines()
    assert "first divergence: byte 7 at device time 0.001000 s (seq 0)" in lines[3]
    assert lines[4].startswith("  seq 0: SUPPLY_OUT 0x") and " V); XGYRO_OUT 0x" in lines[4]
    assert "ZGYRO_OUT 0x" in lines[4] and "deg/s)" in lines[4]
    assert "... and 199 more changed frames" in p.stdout
    assert "xbee" not in p.stdout  # --port
    assert lines[-1] == "different"


def test_json(runs):
    p = navtwin("diff", runs["one"], runs["two"], "--json", "--max", 2)
    assert p.returncode == 1
    d = json.loads(p.stdout)
    assert d["equal"] is False and list(d["ports"]) == ["sins", "xbee", "nanoloc"]
    s = d["ports"]["sins"]
    first = s["first_divergence"]
    assert (first["offset"], first["t_device_ns"]) == (7, 1_000_000)
    assert (first["frame"]["key"], first["frame"]["by"], first["frame"]["offset"]) == (0, "seq", 0)
    assert s["summary"]["changed"] == 200 and len(s["changed"]["shown"]) == 2
    z = next(f for f in s["changed"]["shown"][0]["fields"] if f["field"] == "ZGYRO_OUT")
    assert z["unit"] == "deg/s" and z["delta"] == pytest.approx(z["b_value"] - z["a_value"])


def test_flipped_bit_in_a_byte_file(runs, tmp_path):
    a = runs["one"] / "sins.bin"
    b = tmp_path / "b.bin"
    data = bytearray(a.read_bytes())
    data[3 * sins.FRAME_SIZE + 10] ^= 0x80
    b.write_bytes(bytes(data))
    p = navtwin("diff", "--format", "sins", a, b)
    assert p.returncode == 1, p.stderr
    assert "first divergence: byte 100 (seq 3)" in p.stdout
    assert "only in A: seq 3 at byte 90" in p.stdout
    assert "decode error only in B: bad_crc at byte 90 (30 bytes)" in p.stdout
    assert "changed 0, only in A 1, only in B 0" in p.stdout


@pytest.mark.parametrize("args, words", [
    (("{one}", "{tmp}"), ("no recording.json", "--format")),
    (("{one}", "{tmp}/missing"), ("no recording.json",)),
    (("{one}/sins.bin", "{one}/sins.bin"), ("no recording.json", "give --format")),
    (("--format", "sins", "{one}", "{one}"), ("a directory", "drop --format")),
    (("--format", "sins", "{one}/sins.bin", "{tmp}/missing"), ("no such file",)),
    (("--format", "nope", "{one}/sins.bin", "{one}/sins.bin"), ("invalid choice: 'nope'",)),
    (("{one}", "{two}", "--port", "nope"), ("--port nope in neither recording",)),
    (("{one}", "{two}", "--max", "-1"), ("--max",)),
])
def test_bad_input_exits_2_in_one_line(runs, tmp_path, args, words):
    argv = [a.format(one=runs["one"], two=runs["two"], tmp=tmp_path) for a in args]
    line = one_line_error(navtwin("diff", *argv), *words)
    assert "Traceback" not in line


def test_help_names_every_option():
    p = navtwin("diff", "--help")
    assert p.returncode == 0
    for option in ("--format", "--port", "--max", "--time-tolerance", "--json", "--api1",
                   "--gyro-range", "0 equal, 1 different, 2 bad input"):
        assert option in " ".join(p.stdout.split()), option


@pytest.mark.pty
def test_the_testing_guides_golden_test(tmp_path):
    """docs/testing.md's regression test, as a user's project runs it: it passes against a
    golden of the same seed, and fails with the diff against one of another seed."""
    text = (ROOT / "docs" / "testing.md").read_text(encoding="utf-8")
    section = text.split("## A byte-stream regression test", 1)[1].split("\n## ", 1)[0]
    [example] = re.findall(r"^```python\n(.*?)^```", section, re.M | re.S)
    tests = tmp_path / "tests"
    tests.mkdir()
    (tests / "test_office_bytes.py").write_text(example)

    def run_with_golden(seed: int) -> subprocess.CompletedProcess:
        golden = tests / "golden" / "office-seed1"
        p = navtwin("emulate", "--scenario", "office", "--seed", seed, "--speed", "max",
                    "--duration", 2, "--record", golden, "--overwrite", "--quiet",
                    "--link-dir", tmp_path / "links")
        assert p.returncode == 0, p.stderr
        return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               str(tests)], cwd=tmp_path, capture_output=True, text=True,
                              timeout=120)

    p = run_with_golden(1)
    assert p.returncode == 0 and "1 passed" in p.stdout, p.stdout[-3000:]
    p = run_with_golden(2)
    assert p.returncode == 1 and "1 failed" in p.stdout, p.stdout[-3000:]
    assert "first divergence: byte 7 at device time 0.001000 s (seq 0)" in p.stdout
    assert "seq 0: SUPPLY_OUT 0x" in p.stdout
