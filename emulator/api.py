"""Python API: start an emulated lab for your own integration tests.

::

    from navtwin.emulator.api import emulate

    with emulate("office", seed=1, speed="realtime", duration=30) as lab:
        ser = serial.Serial(lab.ports["xbee"], 115200)   # the stable link to the coordinator
        ...
        lab.fault("bit_errors", 5.0, port="xbee", ber=1e-4)   # live control: now, for 5 s
        lab.unplug("sins"); lab.replug("sins")          # the cable pulled and plugged back
        lab.expect("sins", lambda f: f.seq >= 100, timeout=5)   # a SINS frame, by its fields
        lab.expect("xbee", b"\x7e", timeout=5)         # bytes (or re.compile(rb"...")) on the raw stream
        lab.expect_none("nanoloc", lambda f: f.anchor == 3, within=2)
        lab.unplug("sins"); lab.idle("sins", 1.0)      # no byte for 1 s
        summary = lab.wait_done(timeout=60)             # or leave the block: the lab is stopped

The lab runs as a subprocess of ``navtwin emulate`` (the same program users run), so its
state, threads and signal handling stay out of the test process, and a crash or hang of
either side cannot take the other down. Each lab gets its own private link directory
(``mkdtemp``, mode 0700) unless ``link_dir`` is given, so labs can run side by side.

Expectations (emulator.expect): ``expect``, ``expect_none`` and ``idle`` read the port as a
client would (its declared format, the scenario's API mode), so the port they read is theirs:
a test's own code reads the other ports, or reads this one after its expectations. Their
timeouts are device time in a virtual-time lab (``speed="max"`` or a factor), wall time in a
real-time one; a failure is an AssertionError (``ExpectTimeout``, ``Unexpected``) naming what
was awaited, where, for how long, and the last frames decoded with their fields.
"""
from __future__ import annotations

import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from typing import Iterator

from .control import Control
from .expect import ExpectError, ExpectTimeout, PortWatch, Unexpected
from .scenario import load_scenario


class EmulatorError(RuntimeError):
    """The emulator failed to start or ended badly; the message includes its stderr."""


class Lab:
    """A running ``navtwin emulate`` subprocess."""

    def __init__(self, args: list[str], ready_timeout: float, scenario: str | None = None) -> None:
        self._scenario_ref = scenario  # for the ports' rates, API mode and gyro range
        self._watches: dict[str, PortWatch] = {}
        self._stderr = tempfile.TemporaryFile()
        self.process = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                        stderr=self._stderr)
        self._buf = b""
        self.summary: dict | None = None
        try:
            self.info = self._line(ready_timeout)
        except BaseException:
            self._kill()
            raise
        if not self.info.get("ready"):
            self._kill()
            raise EmulatorError(f"unexpected first line from the emulator: {self.info}")
        self.ports: dict[str, str] = self.info["ports"]  # port name -> stable link
        self.pts: dict[str, str] = self.info["pts"]  # port name -> /dev/pts/N
        self.control = Control(self.info["link_dir"])  # live control (emulator.control)

    # live control: break the lab at the moment the test chooses
    def fault(self, kind: str, duration_s: float | None = None, **settings) -> dict:
        """Inject a fault of *kind* (a scenario [[faults]] kind, without start_s/end_s) now,
        for *duration_s* or until :meth:`clear`; the reply has its ``id``."""
        return self.control.fault(kind, duration_s, **settings)

    def clear(self, id: int | None = None) -> dict:
        """End live fault *id*, or all of them."""
        return self.control.clear(id)

    def unplug(self, port: str) -> dict:
        """Pull *port*'s cable: its link vanishes, its clients read a hang-up."""
        return self.control.unplug(port)

    def replug(self, port: str) -> dict:
        """Plug *port* back: a new PTY behind the same link (``ports[port]``)."""
        reply = self.control.replug(port)
        self.pts[port] = reply["pts"]
        return reply

    def reset(self, device: str, duration_s: float | None = None, vehicle: int | None = None) -> dict:
        """Power-cycle ``"board"`` (the SINS board: its counter starts again) or
        ``"coordinator"`` (modem status 0x00, 0x06) now, off for *duration_s* (0.5 s); of car
        *vehicle* (default 1; a coordinator of its own with per-vehicle networks)."""
        return self.control.reset(device, duration_s, vehicle)

    def status(self) -> dict:
        return self.control.status()

    # expectations on the ports (emulator.expect)
    def expect(self, port: str, match, timeout: float):
        """Wait for *match* on *port*: bytes or a compiled bytes regex (searched in the raw
        stream; returns the ``re.Match``), or a predicate on each decoded frame (given a
        protocols.match.FrameView: ``f.type``, ``f.seq``, ``f.status``, ``f.record``; returns
        the matching one). The stream is consumed up to the match: the next expect on the
        port starts after it. *timeout*: device seconds (virtual time) or wall seconds;
        :class:`ExpectTimeout` after it."""
        return self._watch(port).expect(match, timeout)

    def expect_none(self, port: str, match, within: float) -> None:
        """:class:`Unexpected` if *match* comes on *port* within *within* s from now."""
        self._watch(port).expect_none(match, within)

    def idle(self, port: str, seconds: float) -> None:
        """:class:`Unexpected` if any byte comes on *port* within *seconds* from now."""
        self._watch(port).idle(seconds)

    def _watch(self, port: str) -> PortWatch:
        if port not in self._watches:
            scenario = load_scenario(self._scenario_ref or self.info["scenario"])
            self._watches[port] = PortWatch(self, port, scenario)
        return self._watches[port]

    def _line(self, timeout: float) -> dict:
        """The next JSON line on the emulator's stdout, waiting at most *timeout* s."""
        deadline = time.monotonic() + timeout
        fd = self.process.stdout.fileno()
        while b"\n" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                raise TimeoutError(f"no line from the emulator within {timeout:g} s")
            chunk = os.read(fd, 65536)
            if not chunk:
                self.process.wait(timeout=10)
                raise EmulatorError(f"emulator exited with status {self.process.returncode}: "
                                    f"{self.stderr().strip() or 'no message'}")
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return json.loads(line)

    def stderr(self) -> str:
        """What the emulator wrote on stderr so far (progress lines, errors)."""
        self._stderr.seek(0)
        return self._stderr.read().decode("utf-8", "replace")

    def running(self) -> bool:
        return self.process.poll() is None

    def wait_done(self, timeout: float) -> dict:
        """Wait for the run to end (duration reached or stopped); returns the ``done`` line."""
        if self.summary is None:
            deadline = time.monotonic() + timeout
            line = self._line(timeout)
            if not line.get("done"):
                raise EmulatorError(f"unexpected line from the emulator: {line}")
            self.summary = line
            self.process.wait(timeout=max(0.1, deadline - time.monotonic()))
            if self.process.returncode != 0:
                raise EmulatorError(f"emulator exited with status {self.process.returncode}: "
                                    f"{self.stderr().strip()}")
        return self.summary

    def stop(self, timeout: float = 60.0) -> dict:
        """Stop the lab as SIGTERM does (links removed, recording completed); the ``done`` line."""
        if self.summary is None and self.running():
            self.process.send_signal(signal.SIGTERM)
        return self.wait_done(timeout)

    def _kill(self) -> None:
        if self.running():
            self.process.kill()
        self.process.wait()
        self.close()

    def close(self) -> None:
        for watch in self._watches.values():
            watch.close()
        self.process.stdout.close()
        self._stderr.close()


def command(scenario: str, *, seed: int | None = None, speed: str | float = "realtime",
            duration: float | None = None, link_dir: str | os.PathLike | None = None,
            record: str | os.PathLike | None = None, overwrite: bool = False,
            timing: str = "auto") -> list[str]:
    """The ``navtwin emulate`` command line for these settings (run with this Python)."""
    args = [sys.executable, "-m", "navtwin", "emulate", "--scenario", str(scenario),
            "--speed", str(speed), "--timing", timing]
    for flag, value in (("--seed", seed), ("--duration", duration), ("--link-dir", link_dir),
                        ("--record", record)):
        if value is not None:
            args += [flag, str(value)]
    if overwrite:
        args.append("--overwrite")
    return args


@contextmanager
def emulate(scenario: str = "office", *, seed: int | None = None, speed: str | float = "realtime",
            duration: float | None = None, link_dir: str | os.PathLike | None = None,
            record: str | os.PathLike | None = None, overwrite: bool = False,
            timing: str = "auto", ready_timeout: float = 60.0) -> Iterator[Lab]:
    """Start ``navtwin emulate`` and yield the running :class:`Lab` once its ports exist;
    on exit stop it (if still running) and remove its private link directory."""
    private = None
    if link_dir is None:
        private = link_dir = tempfile.mkdtemp(prefix="navtwin-lab-")
    try:
        lab = Lab(command(scenario, seed=seed, speed=speed, duration=duration, link_dir=link_dir,
                          record=record, overwrite=overwrite, timing=timing), ready_timeout,
                  str(scenario))
        try:
            yield lab
        finally:
            try:
                lab.stop()
            finally:  # whatever happened, leave no emulator behind
                if lab.running():
                    lab.process.kill()
                    lab.process.wait()
                lab.close()
    finally:
        if private is not None:
            shutil.rmtree(private, ignore_errors=True)


__all__ = ["emulate", "Lab", "EmulatorError", "command", "ExpectError", "ExpectTimeout",
           "Unexpected"]
