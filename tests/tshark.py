"""tshark for the capture tests: found, or the test skipped (failed where CI requires it), and
what it decodes of a capture with navtwin's Lua dissectors, as rows of field values."""
from __future__ import annotations

import functools
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from navtwin.protocols.capture import dissectors_path

from .helpers import DEADLINE_S


def tshark() -> str:
    """tshark's path; skips the test where it is missing, except in CI (``.ci/run`` sets
    NAVTWIN_TSHARK=required), where that is a failure."""
    path = shutil.which("tshark")
    if path is None:
        if os.environ.get("NAVTWIN_TSHARK") == "required":
            pytest.fail("tshark is not installed; .ci/run requires it (apt-get install tshark)")
        pytest.skip("tshark is not installed (scripts/test installs it when root)")
    return path


def needs_tshark(test):
    """A test that runs tshark itself: skipped where it is missing (failed in CI), as
    :func:`tshark`."""
    @functools.wraps(test)
    def run(*args, **kwargs):
        tshark()
        return test(*args, **kwargs)
    return run


def _run(*args) -> str:
    p = subprocess.run([tshark(), *map(str, args)], capture_output=True, text=True,
                       timeout=DEADLINE_S, env={**os.environ, "HOME": "/nonexistent"})
    assert p.returncode == 0, p.stderr
    return p.stdout


def fields(capture: Path, *names: str, where: str = "") -> list[list[list[str]]]:
    """Per packet (those matching the display filter *where*), per field in *names*, every
    occurrence's value as tshark prints it, decoded with navtwin's dissectors."""
    args = ["-r", capture, "-X", f"lua_script:{dissectors_path()}", "-T", "fields",
            "-E", "occurrence=a", "-E", "aggregator=|", "-E", "separator=\t"]
    for name in names:
        args += ["-e", name]
    if where:
        args += ["-Y", where]
    return [[v.split("|") if v else [] for v in line.split("\t")]
            for line in _run(*args).splitlines()]


def packets(capture: Path) -> list[dict]:
    """Every packet's frame layer (interface, time, direction, comment) and raw bytes
    (``frame_raw``), as tshark reads the file by itself (no Lua)."""
    out = json.loads(_run("-r", capture, "-T", "json", "-x", "-J", "frame pkt_comment"))
    rows = []
    for p in out:
        layers = p["_source"]["layers"]
        frame = layers["frame"]
        rows.append({"interface": frame["frame.interface_id_tree"]["frame.interface_name"],
                     "time": frame["frame.time_epoch"],
                     "direction": int(frame.get("frame.packet_flags_tree", {})  # 0: not said
                                      .get("frame.packet_flags_direction", "0"), 16),
                     "comment": layers.get("pkt_comment", {}).get("frame.comment"),
                     "data": bytes.fromhex(layers["frame_raw"][0])})
    return rows
