"""The pytest plugin as a user meets it: a separate pytest run of a user's test file, with the
plugin loaded from its pytest11 entry point."""
import os
import subprocess
import sys
import textwrap

import pytest

from navtwin.emulator import pytest_plugin
from navtwin.emulator.scenario import SCENARIO_NAMES

USER_TESTS = textwrap.dedent('''
    import json, os, serial

    def test_office_fixture(navtwin_office):
        assert navtwin_office.info["scenario"] == "office"
        with serial.Serial(navtwin_office.ports["sins"], 115200, timeout=10) as ser:
            assert ser.read(4)
        assert navtwin_office.running()

    def test_factory_with_options(navtwin_lab, tmp_path):
        lab = navtwin_lab("corridor", duration=3, record=tmp_path / "rec")
        info = lab.info
        assert (info["scenario"], info["speed"], info["seed"]) == ("corridor", "max", 7)
        done = lab.wait_done(timeout=60)
        assert done["done"] and not done["interrupted"]
        assert json.loads((tmp_path / "rec" / "recording.json").read_text())["seed"] == 7
        assert not os.path.lexists(info["ports"]["sins"])

    def test_labs_are_stopped_after_the_test(navtwin_lab):
        lab = navtwin_lab("office")
        pid = lab.process.pid
        with open("pids.txt", "a") as f:
            f.write(f"{pid}\\n")
''')


@pytest.mark.pty
def test_fixtures_and_options_in_a_users_pytest_run(tmp_path):
    (tmp_path / "test_user.py").write_text(USER_TESTS)
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "--navtwin-speed", "max", "--navtwin-seed", "7", "test_user.py"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "3 passed" in out.stdout
    (pid,) = (int(p) for p in (tmp_path / "pids.txt").read_text().split())
    with pytest.raises(ProcessLookupError):  # the lab of the last test was stopped and reaped
        os.kill(pid, 0)


def test_options_are_documented_in_pytest_help(tmp_path):
    out = subprocess.run([sys.executable, "-m", "pytest", "--help", "-p", "no:cacheprovider"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert "--navtwin-speed" in out.stdout and "--navtwin-seed" in out.stdout


def test_one_fixture_per_shipped_scenario():
    for name in SCENARIO_NAMES:
        assert hasattr(pytest_plugin, f"navtwin_{name.replace('-', '_')}")
