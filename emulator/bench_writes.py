"""``navtwin bench emulator-writes``: what the paced loop costs per write, in CPU time (issue 22;
not a test: it measures, it does not assert).

For each N of ``--vehicles`` an office convoy of N vehicles (``--network per-vehicle``, the
cars copies with one board clock, so their chunks fall due in bursts of N) runs in this
process at ``--speed realtime`` on one loop (one worker, the run's timing mode ``auto``),
every one of its 3N ports read from before the clock starts by an epoll reader process
(``bench scale``'s). The loop's cost is its thread's CPU time (``time.thread_time``: the
world's maker process and the reader are not in it) from the clock's start to the run's end,
over the chunks it wrote: ``loop_us_per_write``. Everything the loop does is in it (waking,
the ports' checks every ``CHECK_NS``, taking the world's blocks), as the loop's share of a
vehicle's cost is.

The peer, in the same run: the kernel's part of a write, ``os.write`` of the run's mean chunk
size to each of 3N PTY masters in turn every 10 ms (a burst as the convoy makes them), read by
the same reader, timed the same way: ``write_us``. ``ours_us_per_write`` = the loop's figure
minus the peer's, the Python a write costs on top of its system call.

CPU time, not wall time, so the figures hold on a shared machine (though a loaded machine's
caches make both a little dearer); medians of ``--repeat`` runs, the runs of each N one after
another.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import tempfile
import time
import tty
from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import between, counts, key, takes

from .bench_scale import _reader, late_share

PERIOD_NS = 10_000_000  # the peer's bursts: the SINS board's period
ATTACH_S = 5.0  # the reader opens every port within this, or the run is refused


def _reader_alone(links: dict, until: float, out: str) -> None:
    """``bench scale``'s reader, in a forked child that first closes what it inherited: a
    PTY master of ours left open there would keep its slave from ever hanging up."""
    os.closerange(3, os.sysconf("SC_OPEN_MAX"))
    _reader(links, until, out)


def _read_everything(links: dict, seconds: float, out: str) -> mp.Process:
    """A reader process of *links* (name -> path) for at most *seconds* + 30 s."""
    reader = mp.get_context("fork").Process(
        target=_reader_alone, args=(links, time.monotonic() + seconds + 30, out))
    reader.start()
    return reader


def loop_cost(n: int, seconds: float, seed: int) -> dict:
    """One run: the loop's CPU per write with N vehicles, every port read."""
    from .fleet import convoy
    from .runner import Emulation
    from .scenario import load_scenario

    sc = convoy(load_scenario("office"), n, network="per-vehicle")
    with tempfile.TemporaryDirectory(prefix="navtwin-writes-") as tmp:
        with Emulation(sc, seed, speed=1.0, duration_s=seconds,
                       link_dir=os.path.join(tmp, "links")) as emu:
            reader = _read_everything(dict(emu.links), seconds, os.path.join(tmp, "r.npz"))
            given_up = time.monotonic() + ATTACH_S
            while not all(p.check() for p in emu.ports.values()):  # every write a real one
                if time.monotonic() > given_up:
                    raise RuntimeError("emulator-writes: the reader did not open every port "
                                       f"within {ATTACH_S:g} s; run it on a less loaded machine")
                time.sleep(0.01)
            emu.prepare()  # the world's first second: before the clock, not the loop's cost
            cpu = time.thread_time_ns()
            summary = emu.run()
            cpu = time.thread_time_ns() - cpu
        reader.join()
    ports = summary["ports"].values()
    writes = sum(sum(p["late"].values()) for p in ports)
    late = {}
    for p in ports:
        for k, v in p["late"].items():
            late[k] = late.get(k, 0) + v
    return {"writes": writes, "bytes": sum(p["written"] for p in ports),
            "loop_cpu_s": cpu / 1e9, "loop_us_per_write": cpu / 1e3 / writes,
            "late_1ms_share": late_share(late), "timing": summary["timing"]}


def write_cost(ports: int, size: int, seconds: float = 3.0) -> float:
    """CPU us per ``os.write`` of *size* bytes to a PTY master, in bursts of one write to each
    of *ports* PTYs every PERIOD_NS, every slave read by a forked reader."""
    masters, slaves = zip(*(os.openpty() for _ in range(ports)))
    open_fds = [*masters, *slaves]
    try:
        for master, slave in zip(masters, slaves):
            tty.setraw(slave)
            os.set_blocking(master, False)
        with tempfile.TemporaryDirectory(prefix="navtwin-writes-") as tmp:
            reader = _read_everything({str(i): os.ttyname(s) for i, s in enumerate(slaves)},
                                      seconds, os.path.join(tmp, "r.npz"))
            time.sleep(0.5)  # the reader's opens
            data, cpu, bursts = bytes(size), 0, int(seconds * 1e9 / PERIOD_NS)
            for _ in range(bursts):
                t = time.thread_time_ns()
                for master in masters:
                    os.write(master, data)
                cpu += time.thread_time_ns() - t
                time.sleep(PERIOD_NS / 1e9)
            open_fds = list(slaves)
            for master in masters:  # the reader reads the hang-up and ends
                os.close(master)
            reader.join()
    finally:
        for fd in open_fds:
            os.close(fd)
    return cpu / 1e3 / (bursts * ports)


def writes(vehicles: list[int], seconds: float, repeat: int, seed: int = 1) -> dict:
    """A row per N: the medians of *repeat* runs of :func:`loop_cost` and of the peer."""
    rows = []
    for n in vehicles:
        runs = [loop_cost(n, seconds, seed) for _ in range(repeat)]
        size = round(sum(r["bytes"] for r in runs) / sum(r["writes"] for r in runs))
        peer = [write_cost(3 * n, size) for _ in range(repeat)]
        loop = float(np.median([r["loop_us_per_write"] for r in runs]))
        rows.append({"vehicles": n, "ports": 3 * n, "seconds": seconds, "repeat": repeat,
                     "writes": runs[0]["writes"], "mean_chunk_bytes": size,
                     "loop_us_per_write": loop, "write_us": float(np.median(peer)),
                     "ours_us_per_write": loop - float(np.median(peer)),
                     "runs_loop_us_per_write": [r["loop_us_per_write"] for r in runs],
                     "late_1ms_share": [r["late_1ms_share"] for r in runs],
                     "timing": runs[0]["timing"]})
    return {"benchmark": "emulator-writes", "seed": seed, "cpus": os.cpu_count(),
            "load_average": os.getloadavg(), "rows": rows}


@dataclass(frozen=True)
class Writes:
    """emulator-writes' settings."""
    vehicles: str | None = key(None, "", "the fleet sizes, comma-separated; none = 25,50 (10 quick)",
                               counts(1, 200, "25,50"))
    seconds: float | None = key(None, "s", "real time each run lasts; none = 15 (4 quick)",
                                between(3, 600))
    repeat: int | None = key(None, "", "runs per fleet size, the median counts; none = 3 (1 quick)",
                             between(1, 50))


def benchmarks() -> dict:
    """``navtwin bench emulator-writes`` (a set of navtwin.cli.bench.SETS)."""
    @takes(Writes)
    def emulator_writes(quick: bool, s: Writes) -> dict:
        """emulator: the paced loop's CPU per write with N vehicles in bursts, beside os.write's (goal: ours <= 25 us)"""
        sizes = [int(v) for v in (s.vehicles or ("10" if quick else "25,50")).split(",")]
        return writes(sizes, s.seconds or (4.0 if quick else 15.0),
                      s.repeat or (1 if quick else 3))

    return {"emulator-writes": emulator_writes}
