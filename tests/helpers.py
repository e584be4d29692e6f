"""What the tests share, written once: the navtwin command (as a process and in process) and
the office lab's constants.

The constants are read from the shipped host config ``office`` by navtwin's own loader, so a
test never types the survey again; tests/cli/test_host.py checks that config against the
paper's survey (shared/specs/scenarios.md). Fixtures live in tests/conftest.py.
"""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import threading
from pathlib import Path

from navtwin.cli.main import main
from navtwin.host import config as host_config
from navtwin.host.settings import EstimatorConfig
from navtwin.host.tracks.fusion import TightSettings
from navtwin.host.tracks.ukf import UkfSettings

ROOT = Path(__file__).resolve().parent.parent

#: navtwin as a user runs it, from this environment (the console script runs the same main).
NAVTWIN = [sys.executable, "-m", "navtwin"]
#: A generous deadline for one navtwin command (the box is shared and loaded).
DEADLINE_S = 120.0


def navtwin(*args, timeout: float = DEADLINE_S, text: bool = True,
            **kw) -> subprocess.CompletedProcess:
    """``navtwin *args`` as a process, its output captured (as text unless *text* is false);
    the other keywords go to :func:`subprocess.run` (``input``, ``cwd``, ``env``...)."""
    return subprocess.run([*NAVTWIN, *map(str, args)], capture_output=True, text=text,
                          timeout=timeout, **kw)


def run_cli(capsys, *argv) -> tuple[int, str, str]:
    """``navtwin *argv`` in this process: the exit code (argparse's exits too), stdout, stderr."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


def _error_line(code: int, out: str, err: str, words) -> str:
    """A user error as navtwin reports one: exit 2, nothing on stdout, one line on stderr
    (holding *words*); that line."""
    assert code == 2, err
    assert out == "", out
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def one_line_error(result: subprocess.CompletedProcess, *words: str) -> str:
    """The error line of a navtwin process that met a user error (:func:`_error_line`)."""
    return _error_line(result.returncode, result.stdout, result.stderr, words)


def cli_error(capsys, *argv) -> str:
    """The error line of ``navtwin *argv`` run in this process (:func:`_error_line`)."""
    return _error_line(*run_cli(capsys, *argv), ())


#: The office lab of paper 000 as the host knows it.
OFFICE = host_config.load("office")
#: ``{anchor id: (x, y, z)}`` of the office survey, m.
OFFICE_ANCHORS = OFFICE.anchors
#: Where the vehicle stands at power-up, m.
OFFICE_START = OFFICE.vehicles[0].start
LATITUDE_DEG = OFFICE.latitude_deg
#: Local gravity of the lab, m/s^2.
GRAVITY = OFFICE.local_gravity
#: ``{anchor id: (x, y, z)}`` of paper 001's corridor survey, m.
CORRIDOR_ANCHORS = host_config.load("corridor").anchors


def office_config(**overrides) -> EstimatorConfig:
    """The estimator's settings in the office lab: the shipped ``office`` host config's
    (its anchors, site, start and [filters]), with *overrides* (``alignment_s=2.0``, ...)."""
    return dataclasses.replace(OFFICE.estimator_config(), **overrides)


def tight(method: str) -> dict:
    """An EstimatorConfig's ``settings`` that make the EKF and UKF measure ranges by *method*
    (``"toa"``: each range, ``"tdoa"``: each cycle's differences; their ``tight`` key)."""
    return {"ekf": TightSettings(tight=method), "ukf": UkfSettings(tight=method)}


def fifo_permitted() -> bool:
    """Whether this process may take SCHED_FIFO, asked of the kernel on a thread of its own."""
    answer = []

    def probe():
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            answer.append(True)
        except PermissionError:
            answer.append(False)

    t = threading.Thread(target=probe)  # the probe's policy dies with its thread
    t.start()
    t.join()
    return answer[0]
