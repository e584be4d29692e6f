"""Start-up: a navtwin process imports what its command needs and no more. Every test, ``ctl``
call and lab start pays the imports; the CPU figures are the benchmark's (``navtwin bench
startup``, docs/performance.md), these tests assert the imports only."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from navtwin.emulator.api import emulate

#: What no quick command needs: scipy alone cost every process 0.4-1.2 CPU-s.
HEAVY = {"numpy", "scipy", "matplotlib", "rich", "construct", "serial", "dask", "distributed",
         "pyarrow"}
#: What no --help needs (the host's options name its configs and tracks: numpy may come).
NEVER_FOR_HELP = HEAVY - {"numpy", "construct"}

PROBE = """
import json, sys
from navtwin.cli.main import main
try:
    code = main(sys.argv[2:])
except SystemExit as e:
    code = e.code
with open(sys.argv[1], "w") as f:
    json.dump({"code": code, "modules": sorted({m.split(".")[0] for m in sys.modules})}, f)
"""


def imports_of(tmp_path, *argv) -> tuple[int, set[str], str]:
    """Exit status, top-level modules imported, and stdout of ``navtwin ARGV``."""
    out = tmp_path / "modules.json"
    done = subprocess.run([sys.executable, "-c", PROBE, str(out), *argv], capture_output=True,
                          text=True, timeout=120)
    probe = json.loads(out.read_text())
    return probe["code"], set(probe["modules"]), done.stdout


def test_version_imports_nothing_heavy(tmp_path):
    code, modules, stdout = imports_of(tmp_path, "--version")
    assert code == 0 and stdout.startswith("navtwin ")
    assert modules & HEAVY == set()


def test_ctl_status_imports_nothing_heavy(tmp_path):
    links = tmp_path / "links"
    with emulate("office", duration=60, link_dir=links):
        code, modules, stdout = imports_of(tmp_path, "ctl", "status", "--link-dir", str(links))
    assert code == 0 and json.loads(stdout)["ok"] is True
    assert modules & HEAVY == set()


@pytest.mark.parametrize("command", ["audit", "bench", "calibrate", "ctl", "decode", "demo",
                                     "emulate", "host", "replay", "lab", "report", "sweep"])
def test_help_imports_no_scipy(tmp_path, command):
    code, modules, stdout = imports_of(tmp_path, command, "--help")
    assert code == 0 and "usage: navtwin" in stdout
    assert modules & NEVER_FOR_HELP == set()


def test_emulate_imports_no_scipy_to_its_ready_line(tmp_path):
    """The scenario's clothoid corners need the Fresnel integrals before the ready line:
    computed in numpy (emulator/fresnel.py), since scipy.special alone cost 0.25-0.3 CPU-s."""
    proc = subprocess.Popen([sys.executable, "-c", EMULATE_TO_READY, str(tmp_path / "links")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready = json.loads(proc.stdout.readline() or "{}")
        modules = json.loads(proc.stdout.readline() or "[]")
    finally:
        proc.kill()
        _, err = proc.communicate(timeout=60)
    assert ready.get("ready") is True, err
    assert [m for m in modules if m.split(".")[0] == "scipy"] == []


#: navtwin emulate, and at its ready line the modules imported until then
EMULATE_TO_READY = """
import json, sys
import navtwin.cli.emulate as cli

def emit(obj, _emit=cli._emit):
    _emit(obj)
    if obj.get("ready"):
        print(json.dumps(sorted(sys.modules)), flush=True)

cli._emit = emit
from navtwin.cli.main import main
main(["emulate", "--scenario", "office", "--quiet", "--link-dir", sys.argv[1]])
"""


def test_entry_points_are_read_once_per_process():
    """Each registry asks for its group (commands, fault kinds, tracks); importlib.metadata
    reads every installed package whichever group is asked, so one read serves them all."""
    done = subprocess.run([sys.executable, "-c", COUNT_READS], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == 1


#: the process reads for the commands, the fault kinds and the tracks (twice)
COUNT_READS = """
import importlib.metadata, json
reads = []
real = importlib.metadata.entry_points
importlib.metadata.entry_points = lambda **select: reads.append(select) or real(**select)
from navtwin.cli.main import build_parser
build_parser()
import navtwin.emulator.faults
from navtwin.host import tracks
tracks.names(), tracks.names()
print(len(reads))
"""
