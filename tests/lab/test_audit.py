"""navtwin audit: a live run of the lab with line faults passes it; each kind of unaccounted
loss, made on purpose in a copy of the recordings, fails it."""
import json
import os
import shutil
import subprocess
import sys

import pytest

from navtwin.lab import audit as audit_mod
from navtwin.lab.orchestrator import Watch, run_lab
from navtwin.protocols.stream import nanoloc_decoder

FAULTS = """base = "office"
name = "faulty"

[[faults]]
kind = "bit_errors"
port = "xbee"
ber = 1e-4
start_s = 0
end_s = 100

[[faults]]
kind = "byte_drop"
port = "nanoloc"
probability = 2e-3
start_s = 0
end_s = 100

[[faults]]
kind = "garbage"
port = "xbee"
start_s = 3
end_s = 100

[[faults]]
kind = "latency"
port = "nanoloc"
delay_s = 0.002
jitter_s = 0.001
start_s = 5
end_s = 8
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("audit")
    (d / "faulty.toml").write_text(FAULTS)
    run_lab(str(d / "faulty.toml"), config="office", duration=12, directory=d / "run",
            watch=Watch(open(os.devnull, "w")), plot=False)
    return d / "run"


def _navtwin(*args):
    return subprocess.run([sys.executable, "-m", "navtwin", *args], capture_output=True,
                          text=True, timeout=120)


def _copy(run, tmp_path):
    shutil.copytree(run / "emulator", tmp_path / "emulator")
    shutil.copytree(run / "host", tmp_path / "host")
    return tmp_path / "emulator", tmp_path / "host"


def test_a_live_run_with_line_faults_passes(run):
    result = audit_mod.audit(run / "emulator", run / "host")
    # navtwin lab audited it itself: the same result in its report
    assert json.loads((run / "report.json").read_text())["audit"] == json.loads(json.dumps(result))
    assert result["ok"], audit_mod.report(result)
    xb, nl = result["ports"]["xbee"], result["ports"]["nanoloc"]
    assert xb["injections"] > 0 and nl["injections"] > 0 and nl["timing_injections"] > 0
    assert xb["rejected_bytes"] > 0 and nl["rejected_bytes"] > 0
    assert xb["accepted"] == xb["intact"] > 100 and nl["accepted"] == nl["intact"] > 100
    out = _navtwin("audit", str(run / "emulator"), str(run / "host"))
    assert out.returncode == 0 and "PASS" in out.stdout and len(out.stdout.splitlines()) < 25


def test_a_ledger_that_misses_injections_fails(run, tmp_path):
    emu, host = _copy(run, tmp_path)
    entries = [json.loads(x) for x in (emu / "faults.jsonl").read_text().splitlines()]
    kept = [e for e in entries if e["kind"] != "byte_drop"]
    assert len(kept) < len(entries)
    (emu / "faults.jsonl").write_text("".join(json.dumps(e) + "\n" for e in kept))
    out = _navtwin("audit", str(emu), str(host))
    assert out.returncode == 1, out.stdout
    assert "FAIL nanoloc: the host rejected" in out.stdout and "no injection touched" in out.stdout


def test_host_bytes_the_emulator_never_sent_fail(run, tmp_path):
    emu, host = _copy(run, tmp_path)
    data = bytearray((host / "nanoloc.bin").read_bytes())
    for at in range(len(data) // 3, len(data) // 3 + 200, 40):
        data[at] ^= 0xFF
    (host / "nanoloc.bin").write_bytes(bytes(data))  # same size: the index stays valid
    result = audit_mod.audit(emu, host)
    assert not result["ok"]
    assert any("never sent" in p for p in result["ports"]["nanoloc"]["problems"])


def test_a_host_that_drops_intact_frames_fails(run, monkeypatch):
    calls = []

    class Forgetful:
        """The host's decoder losing every 10th frame it decodes."""

        def decode(self, data):
            out = nanoloc_decoder().decode(data)
            frames = [e for e in out if hasattr(e, "raw")]
            return [e for e in out if e not in frames[::10]]

    real = audit_mod._decoder

    def decoder(port, escaped):
        calls.append(port)
        first = calls.count(port) == 1  # the emulator's stream is decoded first
        return real(port, escaped) if first or port != "nanoloc" else Forgetful()

    monkeypatch.setattr(audit_mod, "_decoder", decoder)
    result = audit_mod.audit(run / "emulator", run / "host")
    problems = result["ports"]["nanoloc"]["problems"]
    assert any("intact frames were not accepted" in p for p in problems), problems


def test_bad_input_is_one_line_and_exit_2(run, tmp_path):
    for args, want in [((str(run / "host"), str(run / "host")), "not an emulator recording"),
                       ((str(run / "emulator"), str(run / "emulator")), "an emulator recording"),
                       ((str(tmp_path / "none"), str(run / "host")), "")]:
        out = _navtwin("audit", *args)
        assert out.returncode == 2 and len(out.stderr.splitlines()) == 1, out.stderr
        assert want in out.stderr and "Traceback" not in out.stderr
