"""The batch engine (issue 23): many seeds of one scenario, their tracks stepped together,
each seed's estimates equal to :func:`navtwin.lab.run.run_in_memory`'s.

A seed's run has two halves, and this engine takes them apart:

1. **Records.** The emulated lab's bytes, decoded and timed by the host's pipeline, become
   the records each vehicle's estimator is given (host.measurements: IMU samples,
   exchanges, ...). :func:`records` runs that half as the in-memory run does, the
   estimator replaced by one that keeps what it is given, so the records are those of
   the byte path by construction. A seed whose tracks all have a twin takes the bulk path
   first: its input chunks straight to the batch's arrays in numpy
   (host.batch.chunks.bulk_stream, bit for bit the same), and the pipeline only when the
   run is not regular (its ``Unbatchable``), on the same chunks. With tracks run per seed
   the records are made by the pipeline: those tracks take record objects, and an
   exchange's RSSI, which the batch's arrays leave out.
2. **Tracks.** The tracks with a batch twin (host.batch.tracks) run for every seed of the
   batch at once (host.batch.estimator.BatchEstimator); the others run per seed with the
   estimator itself, on the same records. A seed that leaves the batch's common path (the
   batch estimator's ``ejected``: a restart, a gap, a numerical reset) runs per seed with
   every track. So every seed has every track's estimates, and a twin only makes them
   faster.

Equality: each seed's estimates equal run_in_memory's to 1e-9 (tests/lab/test_batch.py, on
seeds of every shipped scenario). A track's numbers do not depend on the tracks beside it
(each fusion track predicts to its own time), and a record that only the tracks run per
seed take still moves the batch's filter time, as it moves the estimator's.

Estimates come as columns (:func:`columns`), per track: ``t, x, y, vx, vy, yaw`` (NaN: the
track reports none), ``cov`` (k, 16: the 4x4 of x, y, vx, vy, row-major) and
``extrapolated``, what lab.evaluate scores.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from navtwin.emulator.scenario import Scenario
from navtwin.host.arrival import arrivals, split
from navtwin.host.batch.chunks import bulk_stream
from navtwin.host.batch.estimator import COLUMNS, BatchEstimator, Unbatchable, stream
from navtwin.host.batch.tracks import batchable
from navtwin.host.estimator import Estimator
from navtwin.host import config as host_config
from navtwin.host.pipeline import Pipeline
from navtwin.host.replay import config_for, drive

from .run import lab_ports, lab_ports_together, scenario_of

#: seeds whose emulations are made together (emulator.runner.chunks_together): beyond about
#: 16 a block's numpy calls gain little more, and each seed's chunks wait in memory meanwhile
TOGETHER = 16


class Kept:
    """An estimator that keeps the records the pipeline gives it and estimates nothing."""

    def __init__(self, cfg) -> None:
        self.cfg = cfg
        self.records: list = []
        self.on_innovation = None

    def feed(self, record) -> list:
        self.records.append(record)
        return []

    def stats(self) -> dict:
        return {"records": len(self.records)}


def records(scenario: str | Path | Scenario, seed: int | None = None, *,
            filters: tuple[str, ...] | None = None, duration: float | None = None):
    """The estimator settings of the host's vehicle 1 on *scenario*'s lab (run_in_memory's
    host config and filters) and the records its estimator is given in the run of *seed*."""
    return records_of(*lab_ports(scenario_of(scenario), seed, duration=duration, filters=filters))


def records_of(settings: dict, ports: dict, bauds: dict):
    """:func:`records` of a run's input chunks (lab.run.lab_ports' arrays) under the
    pipeline's *settings*."""
    kw = dict(settings)
    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), make_estimator=Kept, **kw)
    drive(pipe, arrivals(split(ports), bauds), lambda _: None)
    kept = pipe.vehicles[0].estimator
    return kept.cfg, kept.records


def columns(estimates, filters) -> dict[str, dict[str, np.ndarray]]:
    """Estimate objects (host.tracks.base.Estimate) as columns per track (COLUMNS, as the
    batch's), *filters* first (a track without estimates has empty columns)."""
    rows: dict[str, list] = {f: [] for f in filters}
    for e in estimates:
        rows.setdefault(e.filter, []).append(
            (e.t, e.x, e.y, e.vx, e.vy, np.nan if e.yaw is None else e.yaw, *e.cov, e.extrapolated))
    out = {}
    for name, r in rows.items():
        a = np.array(r, dtype=float).reshape(len(r), 23)
        out[name] = dict(zip(COLUMNS, (*a[:, :6].T, a[:, 6:22], a[:, 22].astype(bool))))
    return out


def per_seed(cfg, recs) -> list:
    """The estimator fed *recs* alone: its estimates."""
    est = Estimator(cfg)
    out: list = []
    for r in recs:
        out += est.feed(r)
    return out


@dataclass
class Outcome:
    """A batch's result: ``estimates`` (per seed, :func:`columns`' layout), ``batched`` (the
    tracks run as a batch), ``ejected`` (seed -> why it ran per seed), and the CPU seconds of
    each half: ``records_s`` (the byte path to the records), ``batch_s`` (the batched tracks),
    ``per_seed_s`` (the tracks without a twin, and the ejected seeds); ``bulk``: the seeds
    whose records took the bulk path (module doc)."""
    estimates: list
    batched: tuple
    ejected: dict
    records_s: float = 0.0
    batch_s: float = 0.0
    per_seed_s: float = 0.0
    bulk: int = 0


def run(scenario: str | Path | Scenario, seeds, *, filters: tuple[str, ...] | None = None,
        duration: float | None = None) -> Outcome:
    """Every track's estimates for each of *seeds* (module doc). Each seed's records are
    made (by the bulk path where it can), taken by the tracks run per seed and turned into
    a :class:`Stream` (arrays) at once, so a batch holds about a megabyte a seed; a seed the
    batch ejects has its records made again (they are the same) and runs per seed."""
    sc = scenario_of(scenario)
    seeds = list(seeds)
    out: list[dict] = [{} for _ in seeds]
    ejected: dict[int, str] = {}
    cpu = dict.fromkeys(("records", "batch", "per_seed"), 0.0)
    streams, rows, cfg, batched, rest, bulk = [], [], None, (), (), 0
    # each seed's host config, loaded once (lab_ports loads it per seed); a fleet's follower
    # config is made from it per seed
    shared = {} if len(sc.fleet) > 1 else {"config": host_config.load(config_for(sc.name))}

    def made(seed):
        t = time.process_time()
        got = records(sc, seed, filters=filters, duration=duration)
        cpu["records"] += time.process_time() - t
        return got

    lab: list = []  # the next seeds' emulations, made TOGETHER at a time
    for k, seed in enumerate(seeds):
        t = time.process_time()
        if not lab:
            lab = lab_ports_together(sc, seeds[k:k + TOGETHER], duration=duration,
                                     filters=filters, **shared)[::-1]
        kw, ports, bauds = lab.pop()
        c = kw["config"].estimator_config(kw["filters"], 1)  # vehicle 1's, as Kept's
        if cfg is None:
            cfg, batched = c, batchable(c.filters)
            rest = tuple(f for f in c.filters if f not in batched)
            if batched:
                takes = BatchEstimator(replace(cfg, filters=batched), 0).takes()
                others = Estimator(replace(cfg, filters=rest)).takes() if rest else frozenset()
        recs = None
        if batched and not rest:
            try:
                streams.append(bulk_stream(ports, bauds, kw, cfg.imu_gap_s))
                rows.append(k)
                bulk += 1
            except Unbatchable:  # not regular: the pipeline's records, of the same chunks
                recs = records_of(kw, ports, bauds)[1]
        else:
            recs = records_of(kw, ports, bauds)[1]
        cpu["records"] += time.process_time() - t
        if recs is None:  # its Stream is made
            continue
        t = time.process_time()
        if batched:
            try:
                streams.append(stream(recs, takes, others, cfg.imu_gap_s))
                rows.append(k)
            except Unbatchable as e:
                ejected[seed] = str(e)
        if not batched or seed in ejected:
            out[k] = columns(per_seed(c, recs), c.filters)
        elif rest:
            out[k] = columns(per_seed(replace(c, filters=rest), recs), rest)
        cpu["per_seed"] += time.process_time() - t
    if rows:
        t = time.process_time()
        engine = BatchEstimator(replace(cfg, filters=batched), len(rows))
        got = engine.run(streams)
        cpu["batch"] += time.process_time() - t
        for j, k in enumerate(rows):
            if j in engine.ejected:
                ejected[seeds[k]] = engine.ejected[j]
                c, recs = made(seeds[k])
                t = time.process_time()
                out[k] = columns(per_seed(c, recs), c.filters)
                cpu["per_seed"] += time.process_time() - t
            else:
                out[k] = {**got[j], **out[k]}
    if cfg is not None:
        out = [{f: e.get(f) or _empty() for f in cfg.filters} for e in out]
    return Outcome(out, batched, ejected, cpu["records"], cpu["batch"], cpu["per_seed"], bulk)


def _empty() -> dict:
    return columns([], ("_",))["_"]
