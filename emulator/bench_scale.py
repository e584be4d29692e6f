"""``navtwin bench scale``: how many vehicles one machine emulates in real time, read on every
port (issue 22 item 4; not a test: it measures, it does not assert).

For each N of ``--vehicles`` (default 1,10,25,50,75) it runs ``navtwin emulate --vehicles N
--network per-vehicle --speed realtime --duration S --workers W`` as a user would (a
subprocess), and reads EVERY port of every vehicle from the moment the ready line comes:
``--readers`` processes (default one per core), each waiting in ``epoll`` on its share of
the ports and stamping each read with CLOCK_MONOTONIC. Beside them, in the same run, bare
PTY pairs written by a separate process (emulator.bench.BarePairs), one on each schedule the
ports run on (a port's schedule is its chunks' median interval,
emulator.bench.nominal_period_ns: 10 ms for the SINS boards and about that for the
coordinators' packets, 25 ms for the gateways' reports): the floor of the kernel's PTY path
under the same load, for a port of that rate. Each reader reads a pair on each schedule
among its ports (issue 22: "read by the same reader at the same time"), so what the reader
itself adds (its turn for a core, its other ports' reads) falls on the port and its peer
alike; the bench's own process reads one more on each schedule alone, for comparison
(``bare_pty_alone``). A 40 Hz port's p99 is the tail of
2.5x fewer intervals than a 100 Hz port's, so a stall of the whole machine weighs 2.5x as
much in it: judged against the 100 Hz pair, the gateways' ports missed where the SINS
ports, on that pair's own schedule, did not.

What each port should carry, and when, is the same scenario and seed made in memory at
full speed (its chunks' sizes and device times: bytes and times are the same at every
speed). A chunk has arrived with the read that completes its last byte (the reader's bytes
start at the port's ``dropped_unplugged`` offset: what was written before the reader was
noticed). Per port:

- period error: |arrival interval - device-time interval| of consecutive chunks, p50, p99
  and max (for a bare pair, |interval - its period| is the same measure), and its p99's
  ratio to the pair on the port's schedule that its reader read (and to the bench's own);
- frames read against frames written: lost = written - read (leaving out the chunks of the
  last TAIL_NS, which the emulator's closing PTYs may take with them, and those written
  before the reader was there);
- drift: the last chunk's lateness against the first's, on the absolute schedule.

Per N: the emulator's CPU per vehicle as a fraction of a core in steady state (its process
and descendants, workers and makers, from /proc over the bare pairs' window: the goal's
figure), and over the whole run (``os.wait4``'s rusage: start-up included, which a short
run spreads over few seconds), the readers' own CPU (a Python reader of hundreds of PTYs
costs a core's fraction too: it is reported so its share of the load is seen), the summed
lateness histograms of the done line, the worst port (the largest ratio to its bare pair)
and its ratio. The median port's ratio is given too: the goal asks the worst of 3N p99s,
each a noisy figure, to be within GOAL_RATIO of one bare pair's, which the worst of many
misses even where every port's law is the bare pair's; the median says where the typical
port is.

``largest_n_meeting_goal``: the largest N with every port's p99 within GOAL_RATIO of its bare
pair's, no frame lost and at most GOAL_CORE of a core per vehicle (issue 22's goals), and at
most GOAL_LATE_SHARE of the emulator's writes 1 ms late or more (:func:`meets_goal`: why).

``--repeat R`` runs every N R times (all the Ns, then again: a quiet or busy stretch of the
machine falls on every N alike) and gives, beside each run's row, one row per N of the
runs' medians (:func:`medians`): the worst of 3N p99s against one bare pair's is a noisy
figure, and one run says little about the goal on a shared machine. The largest N is then
the median rows' (how many runs met the goal is given per N).
"""
from __future__ import annotations

import json
import math
import multiprocessing as mp
import os
import select
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navtwin.common.schema import Check, between, counts, key, takes

from .bench import (FRAME_BYTES, BarePairs, arrivals, cpu_s, nominal_period_ns, period_errors,
                    period_key, read_pairs)

GOAL_RATIO = 1.2  # a port's reader-side p99 over the bare PTY's
GOAL_CORE = 0.02  # of a core per vehicle
GOAL_LATE_SHARE = 0.01  # of the emulator's writes 1 ms late or more (its schedule kept)
SLIPPED = ("<3ms", "<10ms", ">=10ms")  # the lateness bins from 1 ms up
TAIL_NS = 100_000_000  # chunks ending this close to the end are left out: the emulator
#                        closes its PTYs at once, and a reader may not have read them yet


def port_figures(read_t, read_n, sizes, ends_ns, skipped: int) -> dict:
    """One port's figures: *sizes* and *ends_ns* of the chunks written (device time),
    *skipped* bytes written before the reader was there."""
    offsets = np.cumsum(sizes) - skipped
    total = int(np.sum(read_n))
    whole = (offsets > 0) & (offsets <= total)  # chunks read whole
    t = arrivals(offsets[whole], np.cumsum(read_n), read_t)
    dev = np.asarray(ends_ns, dtype=np.int64)[whole]
    out = {"read": int(whole.sum())}
    if len(t) >= 2:
        err = period_errors(t, dev)
        late = (t - t[0]) - (dev - dev[0])
        out.update(p50_ms=float(np.percentile(err, 50)), p99_ms=float(np.percentile(err, 99)),
                   max_ms=float(err.max()), drift_ms=float(late[-1] / 1e6))
    return out


def _reader(paths: dict, until: float, out: str, want: dict | None = None) -> None:
    """Read *paths* (name -> link) until each hangs up, has brought its *want* bytes (name ->
    bytes: a bare pair, which never hangs up) or *until* (monotonic s); save each read's time
    and size per name, and this process's CPU seconds, to *out* (.npz)."""
    want = want or {}
    ep = select.epoll()
    fds = {}
    for name, path in paths.items():
        fd = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        fds[fd] = name
        ep.register(fd, select.EPOLLIN)
    reads = {name: [] for name in paths}
    got = dict.fromkeys(paths, 0)
    while fds and time.monotonic() < until:
        for fd, events in ep.poll(0.5):
            t = time.monotonic_ns()
            try:
                data = os.read(fd, 65536)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                data = b""
            name = fds[fd]
            if data:
                reads[name].append((t, len(data)))
                got[name] += len(data)
            if not data or got[name] >= want.get(name, math.inf):  # hung up, or all there
                ep.unregister(fd)
                os.close(fd)
                del fds[fd]
    cpu = sum(os.times()[:2])
    np.savez(out, cpu_s=np.array(cpu), **{name: np.array(r, dtype=np.int64).reshape(-1, 2)
                                          for name, r in reads.items()})


def schedule(n: int, seconds: float, seed: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per port of an N-vehicle office convoy: each chunk's size and device end (ns)."""
    from .fleet import convoy
    from .runner import Emulation
    from .scenario import load_scenario

    chunks = defaultdict(list)
    sc = convoy(load_scenario("office"), n, network="per-vehicle")
    with Emulation(sc, seed, speed=None, duration_s=seconds, ports=False,
                   sink=lambda c: chunks[c.port].append((len(c.data), c.end_ns))) as emu:
        emu.run()
    return {p: (np.array([s for s, _ in c]), np.array([e for _, e in c])) for p, c in chunks.items()}


def run_n(n: int, seconds: float, seed: int, workers: str, readers: int) -> dict:
    """One row: N vehicles read on every port, the bare pairs beside them."""
    plan = schedule(n, seconds, seed)
    period = {name: nominal_period_ns(ends) for name, (_, ends) in plan.items()}
    periods = sorted(set(period.values()))
    # a pair on each schedule for each reader (None: the bench's own), the last 0.5 s left out
    owners = [(r, t) for r in [*range(readers), None] for t in periods]
    bare = BarePairs([(t, int((seconds - 0.5) * 1e9 / t)) for _, t in owners])
    index = {owner: i for i, owner in enumerate(owners)}
    with tempfile.TemporaryDirectory(prefix="navtwin-scale-") as tmp, bare:
        proc = subprocess.Popen(
            [sys.executable, "-m", "navtwin", "emulate", "--scenario", "office", "--quiet",
             "--vehicles", str(n), "--network", "per-vehicle", "--speed", "realtime",
             "--duration", f"{seconds:g}", "--seed", str(seed), "--workers", workers,
             "--link-dir", os.path.join(tmp, "links")],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
        ready = json.loads(proc.stdout.readline())
        names = list(ready["ports"])
        reader_of = {p: i % readers for i, p in enumerate(names)}
        ctx = mp.get_context("fork")
        until = time.monotonic() + seconds + 30
        procs = [ctx.Process(target=_reader, args=(
            {**{p: ready["ports"][p] for p in names[i::readers]},
             **{_bare_name(t): bare.paths[index[i, t]] for t in periods}},
            until, os.path.join(tmp, f"r{i}.npz"),
            {_bare_name(t): FRAME_BYTES * bare.frames[index[i, t]] for t in periods}))
            for i in range(readers)]
        for p in procs:
            p.start()
        # meanwhile: the pairs written, this process reading its own; the emulator's CPU
        # (its workers and makers too) over the same window: steady state
        cpu0, w0 = cpu_s(proc.pid), time.monotonic()
        alone = read_pairs(bare, [index[None, t] for t in periods])
        bare.wait()
        steady = (cpu_s(proc.pid) - cpu0) / (time.monotonic() - w0)
        done = json.loads(proc.stdout.readline())
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        proc.stdout.close()
        for p in procs:
            p.join()
        reads, reader_cpu = [], 0.0
        for i in range(readers):
            with np.load(os.path.join(tmp, f"r{i}.npz")) as z:
                reader_cpu += float(z["cpu_s"])
                reads.append({k: z[k] for k in z.files if k != "cpu_s"})
    by_reader = [{t: bare.figures(index[i, t], reads[i][_bare_name(t)]) for t in periods}
                 for i in range(readers)]
    own = {t: bare.figures(index[None, t], alone[index[None, t]]) for t in periods}
    ports, late = {}, defaultdict(int)
    for name in names:
        entry = done["ports"][name]
        sizes, ends = plan[name]
        r = reads[reader_of[name]][name]
        k = int(np.searchsorted(ends, int(seconds * 1e9) - TAIL_NS))  # before the tail
        fig = port_figures(r[:, 0], r[:, 1], sizes[:k], ends[:k], entry["dropped_unplugged"])
        ports[name] = {**fig, "written": k, "reader": reader_of[name],
                       "lost": k - fig["read"] - _skipped_chunks(sizes, entry),
                       "dropped_unplugged": entry["dropped_unplugged"],
                       "dropped_overflow": entry["dropped_overflow"]}
        for k, v in (entry.get("late") or {}).items():
            late[k] += v
    measured = {k: v for k, v in ports.items() if "p99_ms" in v}
    for name, v in measured.items():
        v["p99_ratio_to_bare"] = v["p99_ms"] / by_reader[v["reader"]][period[name]]["p99_ms"]
        v["p99_ratio_to_bare_alone"] = v["p99_ms"] / own[period[name]]["p99_ms"]
    worst = max(measured, key=lambda k: measured[k]["p99_ratio_to_bare"])
    cpu = usage.ru_utime + usage.ru_stime
    return {"vehicles": n, "workers": done.get("workers", ready.get("workers", 1)),
            "seconds": seconds, "cpu_per_vehicle": steady / n,
            "cpu_per_vehicle_whole_run": cpu / seconds / n,
            "reader_cpu_cores": reader_cpu / seconds, "readers": readers,
            "worst_port": worst, "worst_p99_ms": measured[worst]["p99_ms"],
            "worst_max_ms": max(v["max_ms"] for v in measured.values()),
            "p99_ratio_to_bare": measured[worst]["p99_ratio_to_bare"],
            "median_p99_ratio_to_bare": float(np.median(
                [v["p99_ratio_to_bare"] for v in measured.values()])),
            "p99_ratio_to_bare_alone": max(v["p99_ratio_to_bare_alone"] for v in measured.values()),
            "bare_pty": {period_key(t): {
                "frames": min(b[t]["frames"] for b in by_reader),
                "lost": sum(b[t]["lost"] for b in by_reader),
                **{f: float(np.median([b[t][f] for b in by_reader]))
                   for f in ("p50_ms", "p99_ms", "max_ms")},
                "by_reader": [b[t] for b in by_reader]} for t in periods},
            "bare_pty_alone": {period_key(t): own[t] for t in periods},
            "frames_lost": sum(v["lost"] for v in ports.values()),
            "drift_ms": max((v["drift_ms"] for v in measured.values()), key=abs),
            "late": dict(late), "late_1ms_share": late_share(late),
            "timing": done.get("timing"), "status": proc.returncode,
            "ports": ports}


def _bare_name(period_ns: int) -> str:
    """A reader's bare pair on *period_ns*, among its ports (no port is so named)."""
    return f"bare pair {period_key(period_ns)}"


def _skipped_chunks(sizes: np.ndarray, entry: dict) -> int:
    """Chunks written before the reader was noticed (dropped as unplugged, not lost to it)."""
    return int(np.searchsorted(np.cumsum(sizes), entry["dropped_unplugged"], side="right"))


def late_share(late: dict) -> float:
    """The share of writes 1 ms late or more, of a lateness histogram (emulator.timing)."""
    total = sum(late.values())
    return sum(late.get(k, 0) for k in SLIPPED) / total if total else 0.0


def meets_goal(row: dict) -> bool:
    """Every port within GOAL_RATIO of its bare pair's p99, no frame lost, at most GOAL_CORE
    per vehicle, and the emulator's own schedule kept: the bare pair runs on the same cores,
    so an emulator that starves them slows its peer too and the ratio alone would hide it."""
    return (row["p99_ratio_to_bare"] <= GOAL_RATIO and row["frames_lost"] == 0
            and row["cpu_per_vehicle"] <= GOAL_CORE and row["late_1ms_share"] <= GOAL_LATE_SHARE)


#: the figures of a row that :func:`medians` takes the median of
MEDIAN_FIGURES = ("cpu_per_vehicle", "cpu_per_vehicle_whole_run", "reader_cpu_cores",
                  "worst_p99_ms", "worst_max_ms", "median_p99_ratio_to_bare",
                  "p99_ratio_to_bare", "frames_lost", "late_1ms_share")


def medians(rows: list[dict]) -> list[dict]:
    """One row per N of the runs' *rows*: the median of each of MEDIAN_FIGURES and of the
    bare pair's p99, the runs, and how many of them met the goal; in the order the Ns came."""
    by_n: dict[int, list[dict]] = {}
    for r in rows:
        by_n.setdefault(r["vehicles"], []).append(r)
    return [{"vehicles": n, "runs": len(runs),
             **{k: float(np.median([r[k] for r in runs])) for k in MEDIAN_FIGURES},
             "bare_p99_ms": {t: float(np.median([r["bare_pty"][t]["p99_ms"] for r in runs]))
                             for t in runs[0]["bare_pty"]},
             "runs_meeting_goal": sum(meets_goal(r) for r in runs)}
            for n, runs in by_n.items()]


def scale(vehicles: list[int], seconds: float, seed: int = 1, workers: str = "auto",
          readers: int | None = None, ports: bool = False, repeat: int = 1) -> dict:
    """A row per run of each N of *vehicles* (:func:`run_n`; every N, *repeat* times over),
    and the largest N meeting the goals (of the runs' medians when *repeat* > 1)."""
    readers = readers or os.cpu_count() or 1
    rows = []
    for k in range(repeat):
        for n in vehicles:
            print(f"scale: {n} vehicles" + (f", run {k + 1} of {repeat}" if repeat > 1 else "")
                  + " ...", file=sys.stderr, flush=True)
            row = run_n(n, seconds, seed, workers, readers)
            if not ports:
                row.pop("ports")
            rows.append({**row, "run": k + 1} if repeat > 1 else row)
    judged = medians(rows) if repeat > 1 else rows
    meeting = [r["vehicles"] for r in judged if meets_goal(r)]
    return {"benchmark": "scale", "seconds": seconds, "seed": seed, "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "goal": {
                "p99_ratio_to_bare": GOAL_RATIO, "cpu_per_vehicle": GOAL_CORE,
                "late_1ms_share": GOAL_LATE_SHARE},
            "rows": rows, **({"medians": judged} if repeat > 1 else {}),
            "largest_n_meeting_goal": max(meeting, default=None)}


@dataclass(frozen=True)
class Scale:
    """scale's settings."""
    vehicles: str | None = key(None, "", "the fleet sizes run one after another, comma-separated; "
                               "none = 1,10,25,50,75 (1,10 quick)",
                               counts(1, 500, "1,10,50"))
    seconds: float | None = key(None, "s", "real time each fleet runs; none = 30 (5 quick)",
                                between(3, 3600))
    workers: str = key("auto", "", "navtwin emulate --workers: auto or a count",
                       Check(lambda v: v == "auto" or v.isdigit() and 1 <= int(v) <= 64,
                             "must be auto or a count 1..64", "use e.g. auto or 2"))
    readers: int | None = key(None, "", "reader processes; none = one per core", between(1, 64))
    repeat: int = key(1, "", "runs of every N, all the Ns then again; above 1 the goal is "
                      "judged on the runs' medians", between(1, 20))


def benchmarks() -> dict:
    """``navtwin bench scale`` (a set of navtwin.cli.bench.SETS)."""
    @takes(Scale)
    def scale_bench(quick: bool, s: Scale) -> dict:
        """emulator: vehicles in real time, every port read, beside bare PTYs its reader reads too (goal >= 50 at p99 <= 1.2x, <= 0.02 core each)"""
        counts = [int(v) for v in (s.vehicles or ("1,10" if quick else "1,10,25,50,75")).split(",")]
        return scale(counts, s.seconds or (5.0 if quick else 30.0), workers=s.workers,
                     readers=s.readers, repeat=s.repeat)

    return {"scale": scale_bench}
