"""End to end: `navtwin host` as a subprocess on PTYs, stopped by a signal, then replayed.

With the emulator: `navtwin emulate --scenario office --speed realtime --duration 20` and the
host on its PTY links give estimates for every filter, and `navtwin replay` of the host's
own recording prints the same bytes. Without the emulator's help (or as a quicker check) a
test-side feeder writes the synthetic lab's bytes to PTY pairs instead.
"""
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from navtwin.host.tracks import DEFAULT

from ..helpers import NAVTWIN, navtwin
from ..lines import Lines
from . import lab_bytes

pytestmark = [pytest.mark.pty, pytest.mark.slow]

DEADLINE_S = 120.0


class Proc:
    """A subprocess whose stdout and stderr lines are collected as they come."""

    def __init__(self, *argv: str) -> None:
        self.p = subprocess.Popen([*NAVTWIN, *argv], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        self.out, self.err = Lines(self.p.stdout), Lines(self.p.stderr)

    def wait_line(self, lines: Lines, pred, what: str, timeout: float = DEADLINE_S) -> dict:
        try:
            return lines.wait(pred, what, timeout)
        except AssertionError as e:
            raise AssertionError(f"{e}; stderr: {self.err.text()[-2000:]}") from None

    def _join(self) -> None:
        self.out.join()
        self.err.join()

    def stop(self, sig=signal.SIGINT) -> int:
        """Signal the process (unless *sig* is None: it ends by itself); its exit status."""
        if sig is not None and self.p.poll() is None:
            self.p.send_signal(sig)
        rc = self.p.wait(DEADLINE_S)
        self._join()
        return rc


def _host(ports: dict[str, str], tmp_path: Path) -> Proc:
    args = ["host", "--out", str(tmp_path / "live.jsonl"), "--record", str(tmp_path / "rec"),
            "--status-period", "1"]
    for name, path in ports.items():
        args += [f"--{name}", path]
    host = Proc(*args)
    host.wait_line(host.err, lambda o: o.get("status", {}).get("event") == "started",
                   "host start line")
    return host


def _replay_equals_live(tmp_path: Path) -> str:
    live = (tmp_path / "live.jsonl").read_text()
    res = navtwin("replay", tmp_path / "rec")
    assert res.returncode == 0, res.stderr
    assert res.stdout == live
    return live


def _filters(text: str) -> set[str]:
    return {json.loads(x)["filter"] for x in text.splitlines()}


def test_host_process_on_fed_ptys_stops_on_signal_and_replays_byte_for_byte(tmp_path):
    masters, paths = {}, {}
    for name in ("xbee", "nanoloc"):
        masters[name], slave = os.openpty()
        paths[name] = os.ttyname(slave)
        os.close(slave)
    host = _host(paths, tmp_path)
    t0 = time.monotonic_ns()
    for port, data, t_ns in lab_bytes.office(6.0, 31):
        delay = (t0 + t_ns - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)  # pacing the feeder like the devices; nothing waits on it
        os.write(masters[port], data)
    host.wait_line(host.err, lambda o: o.get("status", {}).get("imu") == 600
                   and o["status"]["reports"] == 240, "a status line counting every frame")
    assert host.stop(signal.SIGTERM) == 0
    summary = json.loads(host.err.lines[-1])["summary"]
    assert summary["counts"]["imu"] == 600 and summary["counts"]["reports"] == 240
    live = _replay_equals_live(tmp_path)
    assert _filters(live) == set(DEFAULT)
    for m in masters.values():
        os.close(m)


def test_office_emulator_and_host_live_then_replay(tmp_path):
    emu = Proc("emulate", "--scenario", "office", "--speed", "realtime", "--duration", "20",
               "--link-dir", str(tmp_path / "links"), "--record", str(tmp_path / "emu"), "--quiet")
    ready = emu.wait_line(emu.out, lambda o: o.get("ready") is True, "emulator ready line")
    host = _host({"xbee": ready["ports"]["xbee"], "nanoloc": ready["ports"]["nanoloc"]}, tmp_path)
    emu.wait_line(emu.out, lambda o: o.get("done") is True, "emulator done line",
                  timeout=20 + DEADLINE_S)
    assert emu.stop(None) == 0
    assert host.stop() == 0
    summary = json.loads(host.err.lines[-1])["summary"]
    assert summary["counts"]["imu"] > 1000 and summary["counts"]["reports"] > 400
    live = _replay_equals_live(tmp_path)
    assert _filters(live) == set(DEFAULT)
    # physical consistency, free of the unknown offset between the two processes' clocks:
    # the tightly coupled filters stay near the path the emulated vehicle actually drove
    truth = np.genfromtxt(tmp_path / "emu" / "truth.csv", delimiter=",", names=True)
    path = np.column_stack([truth["x"], truth["y"]])
    for name in ("ekf", "ukf"):
        est = np.array([(e["x"], e["y"]) for e in map(json.loads, live.splitlines())
                        if e["filter"] == name])
        off_path = np.min(np.linalg.norm(est[:, None, :] - path[None, ::10, :], axis=2), axis=1)
        assert np.percentile(off_path, 95) < 1.0, name
