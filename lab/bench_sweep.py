"""``navtwin bench sweep``: a sweep's seeds per CPU-second by each engine, in the same run.

Seeds 1..N of one scenario go through the byte engine (each seed's in-memory run) and seeds
1..M through the batch engine as one of a sweep's tasks (lab.batch: the records per seed, the
tracks with a twin as one batch, the others per seed; M the sweep's batch,
common.limits.BATCH_SIZE, by default: the batched tracks cost less a seed as the batch grows),
each followed by the same scoring (lab.sweep.cells); CPU time of this process, all its threads
(the filters' matrices are too small for a BLAS to thread). The batch engine's CPU is split
into its halves, so the figure says where the time goes. The cells of the seeds both ran are
compared (the largest relative difference of any figure), and 10 000 seeds are projected onto
this machine's cores (a sweep's workers scale: ``navtwin bench host-replays``).

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
                                  f" the sweep's batch, {BATCH_SIZE} (quick: as seeds)",
                                  between(*BATCH_SEEDS))


def _cpu(fn):
    t = time.process_time()
    out = fn()
    return out, time.process_time() - t


def engines(scenario: str = "office", seeds: int = 32, filters=None,
            duration: float | None = None, batch_seeds: int | None = None) -> dict:
    """Seeds per CPU-second of the byte engine on seeds 1..*seeds* and of the batch engine on
    1..*batch_seeds* (default: the sweep's batch size; module doc)."""
    from . import batch, sweep
    from .run import run_in_memory

    sc = load_scenario(scenario)
    filters = tuple(filters or sweep.default_filters(sc))
    batch_seeds = batch_seeds or BATCH_SIZE
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
    with shared_truth():
        outcome, batch_s = _cpu(lambda: batch.run(sc, numbers, filters=filters, duration=duration))
        batch_rows, score_s = _cpu(lambda: [r for s, e in zip(numbers, outcome.estimates)
                                            for r in sweep.cells(sc, s, filters, e)])
    batch_s += score_s
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
            "batched": list(outcome.batched), "ejected": len(outcome.ejected),
            "bulk_records": outcome.bulk,  # seeds whose records skipped the pipeline
            "bytes_seeds_per_cpu_s": round(1 / per_byte, 3),
            "batch_seeds_per_cpu_s": round(1 / per_batch, 3),
            "ratio": round(per_byte / per_batch, 2), "goal_ratio": GOAL_RATIO,
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
