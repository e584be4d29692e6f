"""Cassettes as a user meets them: a separate pytest run of a user's test file, recorded with
``--navtwin-record`` against the real lab, then replayed with no emulator process; and goldens
written by ``--navtwin-update-goldens`` and compared with by ``navtwin_golden``."""
import json
import os
import subprocess
import sys
import textwrap

import pytest

USER_TEST = textwrap.dedent('''
    import os, serial
    from navtwin.protocols import xbee
    from navtwin.protocols.xbee import FrameType

    COMMAND = os.environ.get("AT_COMMAND", "AP").encode()

    def test_my_host_asks_the_coordinator(navtwin_cassette):
        ports = navtwin_cassette("office", seed=3)
        with serial.Serial(ports["xbee"], 115200, timeout=10) as ser:
            ser.write(xbee.build(FrameType.AT_COMMAND, frame_id=7, command=COMMAND, parameter=b""))
            answer = bytes([FrameType.AT_RESPONSE, 7]) + COMMAND  # frame type, id, command
            got = b""
            while answer not in got:
                chunk = ser.read(256)
                assert chunk, f"no answer to {COMMAND}"
                got += chunk
        assert not os.environ.get("FAIL_AFTER"), "the user's own check failed"
''')

# replay runs: no lab may start, and no child process may exist at the end of the test
NO_LAB = textwrap.dedent('''
    import os
    import pytest
    from navtwin.emulator import api

    @pytest.fixture(autouse=True)
    def no_emulator(monkeypatch):
        def refuse(*args, **kwargs):
            raise AssertionError("an emulator was started in a replay")
        monkeypatch.setattr(api.Lab, "__init__", refuse)
        yield
        pid = os.getpid()
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            assert f.read().split() == []
''')


def run(tmp_path, *args, env=None):
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--navtwin-speed", "max", *args, "test_user.py"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})})


@pytest.mark.pty
def test_recorded_against_the_lab_replays_without_it_and_a_changed_write_fails(tmp_path):
    (tmp_path / "test_user.py").write_text(USER_TEST)
    out = run(tmp_path, "--navtwin-record")
    assert out.returncode == 0, out.stdout + out.stderr
    cassette = tmp_path / "cassettes" / "test_my_host_asks_the_coordinator"
    index = json.loads((cassette / "cassette.json").read_text())
    assert (index["scenario"], index["seed"]) == ("office", 3)
    writes = [c for c in index["chunks"] if c["dir"] == "write"]
    assert [c["port"] for c in writes] == ["xbee"] * len(writes)
    assert (cassette / "xbee.write.bin").read_bytes()[:1] == b"\x7e"  # one API frame
    # the coordinator's answer was read after the question was written
    first_write = index["chunks"].index(writes[0])
    read = (cassette / "xbee.read.bin").read_bytes()
    answer_at = read.index(bytes([0x88, 7]) + b"AP")
    later = [c for c in index["chunks"][first_write:] if c["port"] == "xbee" and c["dir"] == "read"]
    assert later and later[0]["offset"] <= answer_at

    # a recording run whose test fails keeps the cassette it had, and says so
    before = {f.name: f.read_bytes() for f in cassette.iterdir()}
    out = run(tmp_path, "--navtwin-record", env={"AT_COMMAND": "ID", "FAIL_AFTER": "1"})
    assert out.returncode == 1, out.stdout + out.stderr
    assert "keeps the cassette it had" in out.stdout
    assert {f.name: f.read_bytes() for f in cassette.iterdir()} == before

    (tmp_path / "conftest.py").write_text(NO_LAB)
    out = run(tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "1 passed" in out.stdout

    out = run(tmp_path, env={"AT_COMMAND": "ID"})
    assert out.returncode == 1, out.stdout + out.stderr
    assert "port xbee: the host code's writes differ from the cassette's" in out.stdout
    assert 'frame 0: command "AP" -> "ID"' in out.stdout  # the diff names the field
    assert "an emulator was started" not in out.stdout


def test_a_missing_cassette_says_how_to_record_it(tmp_path):
    (tmp_path / "test_user.py").write_text(USER_TEST)
    out = run(tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "no cassette at" in out.stdout and "pytest --navtwin-record" in out.stdout
    assert not (tmp_path / "cassettes").exists()


def test_the_flags_are_in_pytest_help(tmp_path):
    out = subprocess.run([sys.executable, "-m", "pytest", "--help", "-p", "no:cacheprovider"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert "--navtwin-record" in out.stdout and "--navtwin-update-goldens" in out.stdout


GOLDEN_TEST = textwrap.dedent('''
    import os
    from navtwin.emulator.api import emulate

    def test_office_bytes(navtwin_golden, tmp_path):
        seed = int(os.environ.get("SEED", "1"))
        with emulate("office", seed=seed, speed="max", duration=1, record=tmp_path / "run") as lab:
            lab.wait_done(timeout=60)
        navtwin_golden(tmp_path / "run")
''')


@pytest.mark.pty
def test_update_goldens_writes_the_golden_the_next_runs_compare_with(tmp_path):
    (tmp_path / "test_user.py").write_text(GOLDEN_TEST)
    out = run(tmp_path)
    assert out.returncode == 1 and "pytest --navtwin-update-goldens" in out.stdout, out.stdout
    out = run(tmp_path, "--navtwin-update-goldens")
    assert out.returncode == 0, out.stdout + out.stderr
    golden = tmp_path / "goldens" / "test_office_bytes"
    assert json.loads((golden / "recording.json").read_text())["seed"] == 1
    out = run(tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    out = run(tmp_path, env={"SEED": "2"})  # another run's bytes: the diff says where
    assert out.returncode == 1, out.stdout + out.stderr
    assert "sins (sins): differs" in out.stdout and "first divergence" in out.stdout
