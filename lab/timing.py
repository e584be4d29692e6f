"""``navtwin bench timing``: how punctually the hosts read the emulated lab's ports while they
run, beside bare PTY pairs in the same run (a benchmark: it measures, it does not assert).

One run: ``navtwin emulate --speed realtime --record`` (with ``vehicles`` N, emulator.fleet's
convoy, its air shared as ``network`` says) and, on its links, the hosts that follow its cars
(lab.fleet.followers: one ``navtwin host --filters F --record`` on ``xbee`` and ``nanoloc``
for one car or cars sharing the air, one per car on its own ports with per-vehicle networks),
each its own process, started as ``navtwin lab`` starts them (lab.orchestrator.start_host,
each host's files named as there), and, in this process at the same time,
emulator.bench's bare PTY pairs, one on each schedule the hosts' ports run on (a port's
schedule: the median interval of its chunks in the scenario's first seconds made in memory,
emulator.bench.port_periods; 10 ms for the coordinator's packets, 25 ms for the gateway's
reports), each written on its exact schedule and read as a host reads (``select``, one
``read(2)``). The window measured starts ``SETTLE_S`` after the last host's ``started``
line and lasts as long as the bare pairs write (``seconds``).

Per port any host reads (keyed by the emulator's name, ``xbee2``; the host that reads it
knows it by its input's, ``xbee``), from the two recordings, on one clock: the emulator's
recording gives each chunk (one write of its device: a frame, a packet, a report) its
schedule, the end of its last byte in device time (``t_device_ns + wire_ns(size, baud)``)
after the emulator's ``t0_monotonic_ns`` (its done line); the host's recording gives each
read its arrival (``t_wall_ns`` after the host's ``t0_monotonic_ns``, its recording's meta).
A chunk is found in the bytes the host read (the host is the port's only reader, so they are
the port's stream from the host's open on, chunk after chunk); it arrived with the read that
brought its last byte. Of the chunks scheduled in the window:

* written and read (``lost`` = written - read: the frame counts, exact when nothing was lost;
  ``frames_lost_total`` over every port);
* the period error ``|arrival interval - scheduled interval|`` (p50, p99, max; the scheduled
  interval is the device times', so the gateway's irregular reports and the coordinator's
  packets count right) and the drift (emulator.bench.period_error);
* the lateness, arrival minus schedule (the reader's and the kernel's delay together), and
  the emulator's own write lateness (its recording's ``t_wall_ns`` against the schedule).

``p99_ratio``: each port's period-error p99 over its bare pair's (``bare_period`` names the
pair; issue 22's goal: at most 1.2 with the host running), ``worst_p99_ratio`` the largest;
``late_p99_ratio``, the same of the lateness; ``max_over_bare_ms``, each port's largest period
error less its pair's (the goal: within 1 ms, on a quiet machine over 10 minutes),
``worst_max_over_bare_ms`` the largest. A reader that wakes late takes two frames or more in
one read: each of their intervals is then off by a whole period, so under stalls longer than
a period the period error's p99 saturates at the period (10 ms on the coordinator's
schedule) while the lateness still tells the stalls apart.

``cpu_cores``: the emulator's (its maker process included) and the hosts' CPU time (user + system, ``/proc/PID/stat``, all
their threads) over the window, as fractions of a core (``host`` the hosts' sum,
``per_host`` each, host 1 first): their cost in steady state, without their start-up.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from navtwin.emulator.api import EmulatorError, emulate
from navtwin.emulator.bench import (arrivals, cpu_s, lateness, period_error, period_key,
                                    port_periods, pty_floors)
from navtwin.protocols.ports import DEFAULT_BAUD
from navtwin.protocols.recording import Recording
from navtwin.protocols.serial import wire_ns

from .fleet import Follower
from .orchestrator import (LabError, _files, _wait_log, fleet_lab, hosts_read, start_host,
                           stop_hosts, write_fleet)

STATUS_PERIOD_S = 2.0  # the hosts' status lines, as navtwin lab asks for them
HOST_START_S = 60.0  # each host's started line comes within this (a loaded box is slow)
SETTLE_S = 1.0  # after the last, before the window: the hosts' first reads, the emulator's attach
WAIT_READ_S = 10.0  # after the emulator has stopped: each host reads what is left, then down
#: a chunk is looked for this far past where the last one ended (bytes a lost part left)
RESYNC_BYTES = 4096


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


def port_row(emulator: Recording, host: Recording, port: str, given: str, emu_t0: int,
             host_t0: int, window: tuple[int, int]) -> dict:
    """The reader-side figures of the emulator's *port*, read by *host* as its input *given*
    (``xbee2`` as ``xbee``), for the chunks scheduled in *window* (monotonic ns)."""
    baud = emulator.meta["ports"][port].get("baud", DEFAULT_BAUD)
    due = [(emu_t0 + c.t_device_ns + wire_ns(len(c.data), baud), c) for c in emulator.chunks(port)]
    chunks = [c for t, c in due if window[0] <= t < window[1]]
    schedule = np.array([t for t, _ in due if window[0] <= t < window[1]], dtype=np.int64)
    written = np.array([emu_t0 + c.t_wall_ns for c in chunks], dtype=np.int64)
    reads = list(host.chunks(given))
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


def fleet_rows(emulator: Recording, hosts: list[tuple[dict[str, str], Recording]], emu_t0: int,
               window: tuple[int, int]) -> dict[str, dict]:
    """A :func:`port_row` for every port any of *hosts* reads, keyed by the emulator's port
    name: each host is its inputs (host input -> the emulator's port it reads,
    lab.fleet.Follower.inputs) and its recording, whose ports carry the input names and
    whose meta its ``t0_monotonic_ns``."""
    return {port: port_row(emulator, rec, port, given, emu_t0, rec.meta["t0_monotonic_ns"], window)
            for inputs, rec in hosts for given, port in inputs.items()}


def _ratios(rows: dict, peer: dict, figure: str) -> dict:
    """Each port's *figure* over its peer's (the bare pair on its schedule)."""
    return {p: r[figure] / peer[p][figure] for p, r in rows.items() if figure in r}


def timing(seconds: float = 60.0, scenario: str = "office", mode: str = "auto",
           filters: str = "all", seed: int | None = None, vehicles: int | None = None,
           network: str | None = None) -> dict:
    """One run of the emulator (timing mode *mode*; with *vehicles* N, emulator.fleet's
    convoy sharing the air as *network* says) with the hosts that follow its cars (tracks
    *filters*, lab.fleet) on their ports and the bare PTY pairs beside them, *seconds*
    measured; the module docstring. LabError (one line) if a side fails."""
    sc, config, hosts = fleet_lab(scenario, vehicles, network, None, None)
    period = port_periods(sc, seed)
    read = {port for h in hosts for port in h.inputs.values()}
    with tempfile.TemporaryDirectory(prefix="navtwin-timing-") as tmp:
        d = Path(tmp)
        run_scenario, config = write_fleet(d, sc, hosts, scenario, config)
        try:
            run = _run(d, seconds, run_scenario, {period[p] for p in read}, mode, seed,
                       hosts, config, filters)
        except EmulatorError as e:
            raise LabError(f"the emulator failed: {str(e).strip().splitlines()[-1]}") from None
        recorded = [Recording(d / _files(h.number)["record"]) for h in hosts]
        if any("t0_monotonic_ns" not in r.meta for r in recorded):
            raise LabError("the host's recording has no t0_monotonic_ns (a host older than "
                           "this benchmark): update navtwin")
        rows = fleet_rows(Recording(d / "emulator"),
                          [(h.inputs, r) for h, r in zip(hosts, recorded)],
                          run["t0_monotonic_ns"], run["window"])
    w0, w1 = run["window"]
    bare, cores = run["bare_pty"], lambda cpu: cpu / ((w1 - w0) / 1e9)
    peer = {p: bare[period[p]] for p in rows}
    ratios = _ratios(rows, peer, "p99_ms")
    over = {p: r["max_ms"] - peer[p]["max_ms"] for p, r in rows.items() if "max_ms" in r}
    return {"benchmark": "timing", "scenario": scenario, "vehicles": len(sc.fleet),
            "network": network, "hosts": len(hosts), "timing": run["timing"],
            "filters": filters, "seconds": (w1 - w0) / 1e9,
            "load_average": [round(x, 2) for x in os.getloadavg()], "ports": rows,
            "bare_pty": {period_key(t): bare[t] for t in sorted(bare)},
            "bare_period": {p: period_key(period[p]) for p in rows}, "p99_ratio": ratios,
            "late_p99_ratio": _ratios(rows, peer, "late_p99_ms"),
            "worst_p99_ratio": max(ratios.values(), default=None),
            "max_over_bare_ms": over, "worst_max_over_bare_ms": max(over.values(), default=None),
            "frames_lost_total": sum(r["lost"] for r in rows.values()),
            "cpu_cores": {"emulator": cores(run["cpu_s"]["emulator"]),
                          "host": cores(sum(run["cpu_s"]["hosts"])),
                          "per_host": [cores(x) for x in run["cpu_s"]["hosts"]]}}


def _run(d: Path, seconds: float, scenario: str | Path, periods: set[int], mode: str,
         seed: int | None, hosts: list[Follower], config: str | None, filters: str) -> dict:
    """The run itself, recorded in *d* (the emulator's recording in ``emulator``, each
    host's files as ``navtwin lab`` names them): the emulator's ``t0_monotonic_ns`` and
    ``timing``, the ``window`` measured (monotonic ns), the bare pair's figures and each
    program's CPU seconds in the window (``emulator``; ``hosts``, in the hosts' order)."""
    logs = [d / _files(h.number)["log"] for h in hosts]
    who = ["the host"] if len(hosts) == 1 else [f"host {h.number}" for h in hosts]
    with emulate(scenario, seed=seed, speed="realtime", record=d / "emulator",
                 timing=mode) as lab:
        procs = [start_host(d, h, lab, config, filters, STATUS_PERIOD_S) for h in hosts]
        try:
            for name, log in zip(who, logs):
                if not _wait_log(log, lambda x: x.get("status", {}).get("event") == "started",
                                 HOST_START_S):
                    raise LabError(f"{name} did not start within {HOST_START_S:g} s: "
                                   f"{_last_line(log)}")
            time.sleep(SETTLE_S)
            pids = [lab.process.pid] + [p.pid for p in procs]
            cpu0, w0 = [cpu_s(p) for p in pids], time.monotonic_ns()
            bare = pty_floors({t: round(seconds * 1e9 / t) for t in periods})
            cpu1, w1 = [cpu_s(p) for p in pids], time.monotonic_ns()
            for name, log, p in zip(who, logs, procs):
                if p.poll() is not None:  # its recording stops where it died: no figure
                    raise LabError(f"{name} exited during the run (status {p.returncode}): "
                                   f"{_last_line(log)}")
            if not lab.running():  # the window ran past the scenario: its end is no figure
                raise LabError("the scenario ended before the window did (the hosts were slow "
                               "to start); measure fewer seconds or run a longer scenario")
            done = lab.stop()
            # the emulator's ports are gone: each host reads what they held, then says so
            hosts_read(logs, WAIT_READ_S)
        finally:
            stop_hosts(procs)
    cpu = [b - a for a, b in zip(cpu0, cpu1)]
    return {"t0_monotonic_ns": done["t0_monotonic_ns"], "timing": lab.info["timing"],
            "window": (w0, w1), "bare_pty": bare,
            "cpu_s": {"emulator": cpu[0], "hosts": cpu[1:]}}
