"""Benchmarks that need both sides: the host on the emulated lab's bytes, the in-memory run,
and the live soak (not tests: they measure, they do not assert).

    python -m navtwin.cli.lab_bench latency [--seconds 20] [--filters all]
    python -m navtwin.cli.lab_bench replay [DIR] [--seconds 60] [--filters all] [--runs 5]
    python -m navtwin.cli.lab_bench in-memory [--scenario office] [--seeds 3]
    python -m navtwin.cli.lab_bench soak [--seconds 600] [--dir DIR]
    python -m navtwin.cli.lab_bench sweep [--scenario office] [--seeds 8] [--workers 2]

``latency``: :func:`navtwin.host.bench.bench_latency` fed the office lab's first --seconds, made in
memory (:func:`navtwin.lab.run.lab_chunks`). ``replay``: :func:`navtwin.host.bench.bench_replay` over DIR (a
host or emulator recording), by default over a host recording of the office lab's first
--seconds. ``in-memory``: seeds per second of the whole scenario through the host, in memory
(:func:`navtwin.lab.run.run_in_memory`) against ``navtwin emulate --speed max --record`` then
``navtwin replay`` (the disk in between). ``soak``: :func:`navtwin.lab.soak.soak`. ``sweep``: seeds
per second of :func:`navtwin.lab.sweep.run`, serial and on a LocalCluster. Each prints one
JSON object.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.host import tracks
from navtwin.host.bench import bench_latency, replay_speeds, write_host_recording
from navtwin.host.replay import replay
from navtwin.protocols.recording import Recording

from .run import lab_chunks, run_in_memory


def latency(seconds: float = 20.0, filters=tracks.DEFAULT, seed: int = 1) -> dict:
    """The host service on PTYs, fed the office lab at its arrival times."""
    kw, chunks = lab_chunks("office", seed, duration=seconds, filters=tuple(filters))
    return bench_latency(kw["config"], kw["filters"], list(chunks), seconds)


def office_replay(seconds: float = 60.0, filters=tracks.DEFAULT, seed: int = 1, runs: int = 5) -> dict:
    """Replay speed of a host recording of the office lab's first *seconds* (median of *runs*)."""
    return office_replays(seconds, {"replay": filters}, seed, runs)["replay"]


def office_replays(seconds: float, sets: dict, seed: int = 1, runs: int = 5) -> dict:
    """:func:`navtwin.host.bench.replay_speeds` of filter *sets* over one host recording of
    the office lab's first *seconds* (recorded with every track, so each set replays the
    same bytes)."""
    kw, chunks = lab_chunks("office", seed, duration=seconds, filters=tracks.names())
    with tempfile.TemporaryDirectory(prefix="navtwin-bench-") as tmp:
        rec = write_host_recording(Path(tmp) / "rec", kw["config"], kw["filters"], chunks,
                                   escaped=kw["escaped"])
        return replay_speeds(rec, {name: tuple(f) for name, f in sets.items()}, runs)


def in_memory(scenario: str = "office", seeds: int = 3) -> dict:
    """Seeds per second of *scenario* through the host: in memory, and recorded then replayed."""
    sc = load_scenario(scenario)
    t = time.perf_counter()
    for seed in range(1, seeds + 1):
        run_in_memory(sc, seed)
    memory_s = time.perf_counter() - t
    with tempfile.TemporaryDirectory(prefix="navtwin-bench-") as tmp:
        t = time.perf_counter()
        for seed in range(1, seeds + 1):
            rec = Path(tmp) / f"seed{seed}"
            with Emulation(sc, seed, speed=None, ports=False, record=rec) as emu:
                emu.run()
            replay(Recording(rec), lambda es: None)
        disk_s = time.perf_counter() - t
    return {"benchmark": "lab-in-memory", "scenario": sc.name, "seeds": seeds,
            "virtual_s": sc.duration_s, "in_memory_seeds_per_s": round(seeds / memory_s, 3),
            "record_replay_seeds_per_s": round(seeds / disk_s, 3),
            "speedup": round(disk_s / memory_s, 2)}


def sweep_rate(scenario: str = "office", seeds: int = 8, workers: int = 2,
               duration: float | None = None) -> dict:
    """Seeds per second of a sweep, in this process and on a LocalCluster of *workers* (its
    start-up timed apart), and their ratio; the two tables are checked equal."""
    from . import sweep

    t = time.perf_counter()
    serial = sweep.run(scenario, range(1, seeds + 1), duration=duration, serial=True)
    serial_s = time.perf_counter() - t
    t = time.perf_counter()
    with sweep.Client(workers=workers) as client:
        start_s = time.perf_counter() - t
        t = time.perf_counter()
        spread = sweep.run(scenario, range(1, seeds + 1), duration=duration, client=client)
        cluster_s = time.perf_counter() - t
    return {"benchmark": "lab-sweep", "scenario": scenario, "seeds": seeds, "workers": workers,
            "virtual_s": duration or load_scenario(scenario).duration_s, "tasks": serial.tasks,
            "serial_seeds_per_s": round(seeds / serial_s, 3),
            "cluster_seeds_per_s": round(seeds / cluster_s, 3),
            "cluster_start_s": round(start_s, 2), "ratio": round(serial_s / cluster_s, 2),
            "same_cells": spread.rows == serial.rows}


def benchmarks() -> dict:
    """The lab's benchmarks for ``navtwin bench`` (a set of navtwin.cli.bench.SETS)."""
    def host_latency(quick: bool = False) -> dict:
        """host: last byte on the PTY -> estimate line, office lab, all filters (goal p99 <= 2 ms)"""
        return latency(5.0 if quick else 20.0)

    def host_replay(quick: bool = False) -> dict:
        """host: replay speed of a host recording of the office lab, 000's five tracks and all
        eight, medians of interleaved runs and their ratio (goal >= 100x with all)"""
        seconds, runs = (10.0, 3) if quick else (60.0, 7)
        r = office_replays(seconds, {"default": tracks.DEFAULT, "all_tracks": tracks.names()},
                           runs=runs)
        return {"benchmark": "host-replay", **r,
                "all_to_default": round(r["default"]["wall_s"] / r["all_tracks"]["wall_s"], 3)}

    def lab_in_memory(quick: bool = False) -> dict:
        """emulator+host: office seeds/s in memory vs emulate --record then replay (goal: faster)"""
        return in_memory("office", 1 if quick else 3)

    def lab_soak(quick: bool = False) -> dict:
        """emulator+host: live soak, second reader and an emulator restart (RSS growth, recovery)"""
        from .soak import soak

        return soak(120.0 if quick else 600.0)

    def lab_sweep(quick: bool = False) -> dict:
        """emulator+host: office seeds/s of navtwin sweep, serial and on 2 LocalCluster workers"""
        return sweep_rate("office", 4 if quick else 8, 2, 20.0 if quick else None)

    def startup(quick: bool = False) -> dict:
        """navtwin: CPU-s to --version, ctl status and emulate's ready line vs importing numpy
        (goal <= 2x)"""
        from .startup import startup as measure

        return measure(3 if quick else 7)

    return {"host-latency": host_latency, "host-replay": host_replay,
            "lab-in-memory": lab_in_memory, "lab-soak": lab_soak, "lab-sweep": lab_sweep,
            "startup": startup}
