"""``navtwin bench timing``: how punctually the host reads the emulated lab's ports while it
runs, beside a bare PTY pair in the same run (a benchmark: it measures, it does not assert).

One run: ``navtwin emulate --speed realtime --record`` and, on its links, ``navtwin host
--filters F --record`` (each its own process, as a user runs them and as ``navtwin lab``
starts them), and, in this process at the same time, emulator.bench's bare PTY pair written on
the SINS board's exact 10 ms schedule and read as the host reads (``select``, one
``read(2)``). The window measured starts ``SETTLE_S`` after the host's ``started`` line and
lasts as long as the bare pair writes (``seconds``).

Per port the host reads, from the two recordings, on one clock: the emulator's recording
gives each chunk (one write of its device: a frame, a packet, a report) its schedule, the
end of its last byte in device time (``t_device_ns + wire_ns(size, baud)``) after the
emulator's ``t0_monotonic_ns`` (its done line); the host's recording gives each read its
arrival (``t_wall_ns`` after the host's ``t0_monotonic_ns``, its recording's meta). A chunk
is found in the bytes the host read (the host is the port's only reader, so they are the
port's stream from the host's open on, chunk after chunk); it arrived with the read that
brought its last byte. Of the chunks scheduled in the window:

* written and read (``lost`` = written - read: the frame counts, exact when nothing was lost);
* the period error ``|arrival interval - scheduled interval|`` (p50, p99, max; the scheduled
  interval is the device times', so the gateway's irregular reports and the coordinator's
  packets count right) and the drift (emulator.bench.period_error);
* the lateness, arrival minus schedule (the reader's and the kernel's delay together), and
  the emulator's own write lateness (its recording's ``t_wall_ns`` against the schedule).

``p99_ratio``: each port's period-error p99 over the bare pair's (issue 22's goal: at most 1.2
with the host running); ``late_p99_ratio``, the same of the lateness. A reader that wakes
late takes two frames or more in one read: each of their intervals is then off by a whole
period, so under stalls longer than a period the period error's p99 saturates at the period
(10 ms on ``sins``'s schedule) while the lateness still tells the stalls apart.

``cpu_cores``: the emulator's and the host's CPU time (user + system, ``/proc/PID/stat``, all
their threads) over the window, as fractions of a core: their cost in steady state, without
their start-up.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from navtwin.emulator.api import EmulatorError, emulate
from navtwin.emulator.bench import arrivals, lateness, period_error, pty_floor, sins_period_ns
from navtwin.host.replay import config_for
from navtwin.protocols.ports import DEFAULT_BAUD
from navtwin.protocols.recording import Recording
from navtwin.protocols.serial import wire_ns

from .orchestrator import HOST_STOP_S, LabError, _wait_log

#: the ports the lab's host reads: the coordinator's (the SINS stream in its 0x90 packets)
#: and the nanoLOC gateway's
HOST_PORTS = ("xbee", "nanoloc")
HOST_START_S = 60.0  # the host's started line comes within this (a loaded box is slow)
SETTLE_S = 1.0  # after it, before the window: the host's first reads, the emulator's attach
WAIT_READ_S = 10.0  # after the emulator has stopped: the host reads what is left, then down
#: a chunk is looked for this far past where the last one ended (bytes a lost part left)
RESYNC_BYTES = 4096


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process *pid* has used so far, its threads included."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _last_line(path: Path) -> str:
    lines = path.read_text(errors="replace").strip().splitlines()
    return lines[-1] if lines else "no output"


def found_ends(chunks: list[bytes], stream: bytes) -> list[int | None]:
    """Where each of *chunks* (in order) ends in *stream*, what a reader read of the port that
    carried them, or None if it is not there (lost). The first is looked for anywhere (the
    reader may have opened mid-chunk); each later one where the last found one ended, or up to
    :data:`RESYNC_BYTES` past it (a chunk the line cut short leaves its part behind)."""
    ends: list[int | None] = []
    cursor = None
    for data in chunks:
        if cursor is None:
            at = stream.find(data)
        else:
            at = stream.find(data, cursor, cursor + len(data) + RESYNC_BYTES)
        if at < 0:
            ends.append(None)
            continue
        cursor = at + len(data)
        ends.append(cursor)
    return ends


def port_row(emulator: Recording, host: Recording, port: str, emu_t0: int, host_t0: int,
             window: tuple[int, int]) -> dict:
    """The reader-side figures of *port* for the chunks scheduled in *window* (monotonic ns)."""
    baud = emulator.meta["ports"][port].get("baud", DEFAULT_BAUD)
    due = [(emu_t0 + c.t_device_ns + wire_ns(len(c.data), baud), c) for c in emulator.chunks(port)]
    chunks = [c for t, c in due if window[0] <= t < window[1]]
    schedule = np.array([t for t, _ in due if window[0] <= t < window[1]], dtype=np.int64)
    written = np.array([emu_t0 + c.t_wall_ns for c in chunks], dtype=np.int64)
    reads = list(host.chunks(port))
    stream = b"".join(r.data for r in reads)
    read_ends = np.cumsum([len(r.data) for r in reads])
    read_ns = np.array([host_t0 + r.t_wall_ns for r in reads], dtype=np.int64)
    ends = found_ends([c.data for c in chunks], stream)
    got = np.array([e is not None for e in ends], dtype=bool)
    arrived = arrivals([e for e in ends if e is not None], read_ends, read_ns)
    row = {"frames_written": len(chunks), "frames_read": int(got.sum()),
           "lost": len(chunks) - int(got.sum())}
    if got.sum() >= 2:
        row.update(period_error(arrived, schedule[got]))
        row.update(lateness(arrived, schedule[got]))
    if len(chunks):
        row.update({f"emulator_{k}": v for k, v in lateness(written, schedule).items()})
    return row


def _ratios(rows: dict, bare: dict, figure: str) -> dict:
    return {p: r[figure] / bare[figure] for p, r in rows.items() if figure in r}


def timing(seconds: float = 60.0, scenario: str = "office", mode: str = "auto",
           filters: str = "all", seed: int | None = None) -> dict:
    """One run of the emulator (timing mode *mode*) with the host (tracks *filters*) on its
    ports and the bare PTY pair beside them, *seconds* measured; the module docstring.
    LabError (one line) if a side fails."""
    config = config_for(Path(scenario).stem)
    if config is None:
        raise LabError(f"scenario: no host config for {scenario!r}; run a scenario named like "
                       "a shipped host config (office, corridor, ...)")
    with tempfile.TemporaryDirectory(prefix="navtwin-timing-") as tmp:
        d = Path(tmp)
        try:
            run = _run(d, seconds, scenario, mode, seed, config, filters)
        except EmulatorError as e:
            raise LabError(f"the emulator failed: {str(e).strip().splitlines()[-1]}") from None
        emulator, recorded = Recording(d / "emulator"), Recording(d / "host")
        if "t0_monotonic_ns" not in recorded.meta:
            raise LabError("the host's recording has no t0_monotonic_ns (a host older than "
                           "this benchmark): update navtwin")
        rows = {p: port_row(emulator, recorded, p, run["t0_monotonic_ns"],
                            recorded.meta["t0_monotonic_ns"], run["window"])
                for p in recorded.meta["host"]["inputs"]}
    w0, w1 = run["window"]
    bare = run["bare_pty"]
    return {"benchmark": "timing", "scenario": scenario, "timing": run["timing"],
            "filters": filters, "seconds": (w1 - w0) / 1e9,
            "load_average": [round(x, 2) for x in os.getloadavg()], "ports": rows,
            "bare_pty": bare, "p99_ratio": _ratios(rows, bare, "p99_ms"),
            "late_p99_ratio": _ratios(rows, bare, "late_p99_ms"),
            "cpu_cores": {k: v / ((w1 - w0) / 1e9) for k, v in run["cpu_s"].items()}}


def _run(d: Path, seconds: float, scenario: str, mode: str, seed: int | None, config: str,
         filters: str) -> dict:
    """The run itself, recorded in *d*: the emulator's ``t0_monotonic_ns`` and ``timing``,
    the ``window`` measured (monotonic ns), the bare pair's figures and each program's CPU
    seconds in the window."""
    period_ns = round(sins_period_ns(scenario))
    log = d / "host.log"
    with emulate(scenario, seed=seed, speed="realtime", record=d / "emulator",
                 timing=mode) as lab:
        with open(log, "wb") as f:
            host = subprocess.Popen(
                [sys.executable, "-m", "navtwin", "host", "--config", config,
                 *(x for port in HOST_PORTS for x in (f"--{port}", lab.ports[port])),
                 "--filters", filters, "--record", str(d / "host"),
                 "--out", str(d / "estimates.jsonl")],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=f)
        try:
            if not _wait_log(log, lambda x: x.get("status", {}).get("event") == "started",
                            HOST_START_S):
                raise LabError(f"the host did not start within {HOST_START_S:g} s: "
                               f"{_last_line(log)}")
            time.sleep(SETTLE_S)
            pids = {"emulator": lab.process.pid, "host": host.pid}
            cpu0, w0 = {k: cpu_s(p) for k, p in pids.items()}, time.monotonic_ns()
            bare = pty_floor(round(seconds * 1e9 / period_ns), period_ns)
            cpu1, w1 = {k: cpu_s(p) for k, p in pids.items()}, time.monotonic_ns()
            if host.poll() is not None:  # its recording stops where it died: no figure
                raise LabError(f"the host exited during the run (status {host.returncode}): "
                               f"{_last_line(log)}")
            done = lab.stop()
            # the emulator's ports are gone: the host reads what they held, then says so
            _wait_log(log, lambda x: x.get("status", {}).get("event") == "port_down",
                     WAIT_READ_S)
        finally:
            if host.poll() is None:
                host.send_signal(signal.SIGTERM)
            host.wait(timeout=HOST_STOP_S)
    return {"t0_monotonic_ns": done["t0_monotonic_ns"], "timing": lab.info["timing"],
            "window": (w0, w1), "bare_pty": bare,
            "cpu_s": {k: cpu1[k] - cpu0[k] for k in pids}}
