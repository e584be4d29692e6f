"""Golden recordings: every shipped scenario reproduces its fixture byte for byte, in virtual
time, and (office, first 2 s) in real time through the real CLI and PTYs.

Regenerate after an intentional change of a device model or scenario (docs/emulator.md):
``navtwin emulate --scenario NAME --duration 10 --speed max --record fixtures/golden/NAME
--overwrite``
"""
import json
import subprocess
import sys

import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import SCENARIO_NAMES, load_scenario
from navtwin.emulator.truth import file_name as truth_file
from navtwin.protocols.recording import Recording

PORTS = ("sins", "xbee", "nanoloc")


def golden(root, name):
    path = root / "fixtures" / "golden" / name
    if not (path / "recording.json").is_file():
        pytest.fail(f"no golden recording for {name}; regenerate it (see this module's docstring)")
    return Recording(path)


def chunks(rec, port, before_ns=None):
    return [(c.data, c.t_device_ns) for c in rec.chunks(port)
            if before_ns is None or c.t_device_ns < before_ns]


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_golden_reproduces_in_virtual_time(root, tmp_path, name):
    gold = golden(root, name)
    sc = load_scenario(name)
    assert (gold.directory / "scenario.toml").read_text() == sc.to_toml(), \
        f"scenario {name} changed since its golden was made; regenerate the golden"
    with Emulation(sc, gold.meta["seed"], speed=None, ports=False,
                   duration_s=gold.meta["duration_s"], record=tmp_path / name) as emu:
        emu.run()
    again = Recording(tmp_path / name)
    assert sorted(again.ports) == sorted(gold.ports) == sorted(sc.ports)  # a car's ports: sins2 ...
    for port in gold.ports:
        assert again.read_bytes(port) == gold.read_bytes(port), f"{name}/{port} bytes differ"
        assert chunks(again, port) == chunks(gold, port), f"{name}/{port} chunking differs"
    for n in range(1, len(sc.fleet) + 1):  # each car's truth
        truth = (tmp_path / name / truth_file(n)).read_bytes()
        assert truth == (gold.directory / truth_file(n)).read_bytes(), f"{name}/{truth_file(n)} differs"


@pytest.mark.pty
def test_first_two_seconds_in_real_time_equal_the_golden(root, tmp_path):
    gold = golden(root, "office")
    out = subprocess.run(
        [sys.executable, "-c", "import sys; from navtwin.cli.main import main; sys.exit(main())",
         "emulate", "--scenario", "office", "--seed", str(gold.meta["seed"]), "--duration", "2",
         "--speed", "realtime", "--link-dir", str(tmp_path / "links"), "--record",
         str(tmp_path / "rt"), "--quiet"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    ready, done = (json.loads(line) for line in out.stdout.splitlines())
    assert ready["ready"] and done["done"] and not done["interrupted"]
    rt = Recording(tmp_path / "rt")
    assert rt.meta["speed"] == "realtime"
    for port in PORTS:
        assert chunks(rt, port) == chunks(gold, port, before_ns=2_000_000_000), port
        assert all(c.t_wall_ns is not None for c in rt.chunks(port))
