"""``navtwin bench sweep``: a sweep's seeds per CPU-second by each engine, in the same run.

Seeds 1..N of one scenario go through the byte engine (each seed's in-memory run) and seeds
1..M through the batch engine as one of a sweep's tasks (lab.batch: the records per seed, the
tracks with a twin as one batch, the others per seed; M by default the batch a serial sweep
takes on this machine, lab.sweep.batch_size_for: the batched tracks cost less a seed as the
batch grows),
each followed by the same scoring (lab.sweep.cells); CPU time of this process, all its threads
(the filters' matrices are too small for a BLAS to thread). The batch engine's CPU is split
into its halves, so the figure says where the time goes. The cells of the seeds both ran are
compared (the largest relative difference of any figure), and 10 000 seeds are projected onto
this machine's cores (a sweep's workers scale: ``navtwin bench host-replays``). Beside them:
the batch's peak memory a seed per second of scenario (what lab.sweep.batch_size_for
reckons with), and the sensor model's own cost a seed (:func:`sensors_floor`) with the ratio
the batch engine would reach were its records only that (``ratio_at_most``).

Goals (issue 23): the batch engine at least 20x the byte engine's seeds per CPU-second, and
10 000 office seeds with all eight tracks within 15 minutes on this 2-core machine.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

from navtwin.common.limits import BATCH_SEEDS, BATCH_SIZE, MAX_DURATION_S
from navtwin.common.schema import between, key, positive, takes
from navtwin.emulator.imu import shared_truth
from navtwin.emulator.scenario import load_scenario
from navtwin.host import tracks

#: all eight tracks of papers 000 and 001, the goal's
EIGHT = ",".join(tracks.EIGHT)
GOAL_RATIO = 20.0
GOAL_MINUTES = 15.0
PROJECTED_SEEDS = 10_000


@dataclass(frozen=True)
class SweepEngines:
    """sweep's settings."""
    scenario: str = key("office", "", "the scenario (a name or a .toml path)")
    seeds: int | None = key(None, "", "seeds 1..N through each engine; none = 32 (4 quick)",
                            between(1, 4096))
    filters: str = key(EIGHT, "", "the tracks, a comma list or all")
    duration: float | None = key(None, "s", "of each run; none = the whole scenario (15 quick)",
                                 positive(hi=MAX_DURATION_S))
    batch_seeds: int | None = key(None, "", "seeds 1..M through the batch engine, one task; none ="
                                  f" a serial sweep's batch here, at most {BATCH_SIZE} (quick: "
                                  "as seeds)", between(*BATCH_SEEDS))


def _peak_from_now() -> None:
    """Start this process's peak resident set (VmHWM) afresh from what it holds now
    (Linux's clear_refs), so a later peak is the work's since, not the byte engine's."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def _cpu(fn):
    t = time.process_time()
    out = fn()
    return out, time.process_time() - t


def sensors_floor(sc, seeds: int, duration: float | None = None) -> float:
    """CPU-s a seed of the ADIS16350 models alone: *seeds* seeds' sensors generated together
    (emulator.imu.generate_together) over the whole run in one call, their true motion
    shared, as in a sweep's task (lab.batch.TOGETHER seeds at a time). No block costs
    anything here, no frame, line, decoder or track: the least any records of these seeds
    can cost with this sensor model."""
    from navtwin.emulator.imu import generate_together
    from navtwin.emulator.world import World

    end = round((duration or sc.duration_s) * 1e9)
    imus = [v.imu for s in range(1, seeds + 1) for v in World(sc, s).vehicles]
    with shared_truth():
        _, cpu = _cpu(lambda: generate_together(imus, 0, end))
    return cpu / seeds


def engines(scenario: str = "office", seeds: int = 32, filters=None,
            duration: float | None = None, batch_seeds: int | None = None) -> dict:
    """Seeds per CPU-second of the byte engine on seeds 1..*seeds* and of the batch engine on
    1..*batch_seeds* (default: a serial sweep's batch on this machine; module doc)."""
    from . import batch, sweep
    from .run import run_in_memory
    from .soak import rss_kb

    sc = load_scenario(scenario)
    filters = tuple(filters or sweep.default_filters(sc))
    batch_seeds = batch_seeds or sweep.batch_size_for(sweep.machine_memory(),
                                                      duration or sc.duration_s)
    numbers = list(range(1, batch_seeds + 1))
    def by_bytes():
        rows = []
        for s in range(1, seeds + 1):
            est, _ = run_in_memory(sc, s, filters=filters, duration=duration)
            rows += sweep.cells(sc, s, filters, batch.columns(est, filters))
        return rows
    # each engine as a sweep's task runs it: its seeds share the truth (shared_truth), each
    # engine computing it afresh
    with shared_truth():
        byte_rows, byte_s = _cpu(by_bytes)
    held = rss_kb(os.getpid())
    _peak_from_now()
    with shared_truth():
        outcome, batch_s = _cpu(lambda: batch.run(sc, numbers, filters=filters, duration=duration))
        # the batch's peak over what the process held before it, a seed per second of
        # scenario (lab.sweep.BATCH_BYTES_PER_SEED_S, which the default batch reckons with)
        per_seed_s = (rss_kb(os.getpid(), "VmHWM") - held) * 1024 / batch_seeds / (
            duration or sc.duration_s)
        batch_rows, score_s = _cpu(lambda: [r for s, e in zip(numbers, outcome.estimates)
                                            for r in sweep.cells(sc, s, filters, e)])
    batch_s += score_s
    floor = sensors_floor(sc, min(batch.TOGETHER, batch_seeds), duration)
    # zip: the cells of the seeds both engines ran, in the same order
    worst = max((abs(a[m] - b[m]) / max(1.0, abs(b[m])) for a, b in zip(batch_rows, byte_rows)
                 for m in sweep.METRICS if isinstance(a[m], float) and isinstance(b[m], float)
                 and math.isfinite(a[m]) and math.isfinite(b[m])), default=0.0)
    cores = os.cpu_count() or 1
    per_byte, per_batch = byte_s / seeds, batch_s / batch_seeds
    return {"benchmark": "sweep", "scenario": sc.name, "seeds": seeds, "batch_seeds": batch_seeds,
            "filters": list(filters),
            "virtual_s": duration or sc.duration_s,
            "bytes_cpu_s_per_seed": round(per_byte, 4),
            "batch_cpu_s_per_seed": round(per_batch, 4),
            "batch_split_cpu_s_per_seed": {
                "records": round(outcome.records_s / batch_seeds, 4),
                "batched_tracks": round(outcome.batch_s / batch_seeds, 4),
                "per_seed_tracks": round(outcome.per_seed_s / batch_seeds, 4),
                "scoring": round(score_s / batch_seeds, 4)},
            "batch_peak_bytes_per_seed_s": round(per_seed_s),
            "batch_bytes_per_seed_s_reckoned": sweep.BATCH_BYTES_PER_SEED_S,
            "batched": list(outcome.batched), "ejected": len(outcome.ejected),
            "bulk_records": outcome.bulk,  # seeds whose records skipped the pipeline
            "bytes_seeds_per_cpu_s": round(1 / per_byte, 3),
            "batch_seeds_per_cpu_s": round(1 / per_batch, 3),
            "ratio": round(per_byte / per_batch, 2), "goal_ratio": GOAL_RATIO,
            # the ratio's ceiling with these tracks and this sensor model: records that cost
            # only the ADIS16350 models' own work (sensors_floor)
            "sensors_floor_cpu_s_per_seed": round(floor, 4),
            "ratio_at_most": round(per_byte / (
                (outcome.batch_s + outcome.per_seed_s + score_s) / batch_seeds + floor), 2),
            "cells_max_relative_difference": worst,
            f"minutes_for_{PROJECTED_SEEDS}_seeds_on_{cores}_cores": round(
                PROJECTED_SEEDS * per_batch / cores / 60, 1),
            "goal_minutes": GOAL_MINUTES}


def benchmarks() -> dict:
    """``navtwin bench sweep`` (a set of navtwin.cli.bench.SETS)."""
    from .bench import _tracks

    @takes(SweepEngines)
    def sweep(quick: bool, s: SweepEngines) -> dict:
        """emulator+host: sweep seeds per CPU-second, batch engine (a sweep's task) vs byte
        engine (goals: 20x; 10 000 office seeds with all eight tracks in 15 min on 2 cores)"""
        seeds = s.seeds or (4 if quick else 32)
        return engines(s.scenario, seeds, _tracks(s.filters), s.duration or (15.0 if quick else None),
                       s.batch_seeds or (seeds if quick else None))

    return {"sweep": sweep}
