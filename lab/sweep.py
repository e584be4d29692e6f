"""Monte Carlo sweeps: one scenario over many seeds, in virtual time, on dask.distributed.

Each seed's estimates come from one of two engines (:data:`ENGINES`), scored by
:func:`navtwin.lab.evaluate.position_errors`; each (scenario, seed, filter) is one cell, a row
of the Parquet output. The batch engine (lab.batch, the default) runs a task's seeds together:
each seed's records as the byte path makes them, then the tracks that have a batch twin
stepped for all of them at once and the others per seed; the byte engine runs each seed in
memory (:func:`navtwin.lab.run.run_in_memory`: no PTY, no file). Their estimates, so their
cells, agree to 1e-9 (tests/lab/test_batch.py). A seed's randomness comes from the seed alone: every draw of the emulator
is from ``emulator.rng.stream(seed, name)``, a Generator on ``SeedSequence(seed,
spawn_key=(crc32(name),))``, and the host draws nothing, so the worker that runs a seed, and the
number of workers, change no cell::

    from navtwin.lab import sweep
    result = sweep.run("office", range(1, 11), out="sweeps/office")   # a LocalCluster
    print(sweep.table(sweep.summarise(result.rows, result.filters, "office")))

Tasks are chunks of seeds: for the batch engine up to ``batch_size`` seeds (as many tasks as
keep the workers busy); for the byte engine worth at least :data:`MIN_TASK_VIRTUAL_S` of
scenario time (about 0.2 s of work here; Dask's overhead is about 1 ms a task): one seed a
task for the shipped scenarios, several for a short ``duration``. A batch that raises is run
again seed by seed by the byte engine; a seed that raises is run once more in its task; a
task lost with its worker is resubmitted once by Dask (``retries=1``); a cell that fails twice
is a row with ``status`` "failed" and the error's line, never dropped. While tasks are out,
the scheduler is asked every :data:`WATCH_S` that no task finishes whether it still answers
and has workers: a sweep whose scheduler is gone, or that has had no worker for
:data:`NO_WORKERS_S`, ends with one line (:class:`SweepError`) rather than waiting forever; the
rows done are in the parts, so the same command finishes it later.

The output directory holds one Parquet file per run (``part-NNNN.parquet``, a row group per
task as it completes) whose metadata (:data:`META_KEY`) names the code version, the scenario's
hash (sha256 of its canonical TOML, :meth:`Scenario.to_toml`), the seeds, the filters, the
duration and the engine. A run into a directory that holds a sweep computes only the cells it
lacks (failed ones again), by either engine; a directory holding a sweep of another scenario
hash, code version, duration or filter set (a record that only some tracks take moves the
filter time, so a cell depends on its companions in the last bits) is refused
(:class:`SweepError`).
"""
from __future__ import annotations

import functools
import json
import math
import os
import re
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from hashlib import sha256
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from navtwin.common import tomlfile
from navtwin.common.limits import BATCH_SEEDS, BATCH_SIZE
from navtwin.emulator.imu import shared_truth
from navtwin.emulator.scenario import Scenario, load_scenario, parse_scenario
from navtwin.host.replay import emulator_settings

from . import batch, evaluate, layouts
from .evaluate import ALPHA, ci_text, decide, mean_ci, p_text, paired
from .provenance import code_version
from .run import run_in_memory, truth
from .vary import Vary, label, overview, variant

#: Scenario seconds a task holds at least (seeds chunked): 0.2-0.7 s of work here.
MIN_TASK_VIRTUAL_S = 10.0
#: A batch task's memory a seed per second of scenario: office's, all eight tracks, is 56-57 kB
#: (``navtwin bench sweep``'s batch_peak_bytes_per_seed_s); this leaves room above that.
BATCH_BYTES_PER_SEED_S = 64_000
#: The share of a worker's memory its batch may take by default (Dask pauses a worker at 80 %).
BATCH_MEMORY_SHARE = 0.5
#: Seconds to wait for a named scheduler before refusing it.
CONNECT_TIMEOUT_S = 10.0
#: While tasks are out, the scheduler is asked this often whether it is there and has
#: workers; a sweep on a cluster without workers for NO_WORKERS_S ends (work never lost: the
#: rows taken are in the parts, and a rerun computes the rest).
WATCH_S = 5.0
NO_WORKERS_S = 60.0
#: The Parquet files' key-value metadata key (a JSON object).
META_KEY = b"navtwin.sweep"
#: The name of a part, the only thing a sweep's output directory holds.
PART = re.compile(r"part-(\d+)\.parquet")
#: Per-seed figures of position_errors kept per cell.
METRICS = ("mean", "max", "rms", "n", "x_min", "x_max", "x_var", "y_min", "y_max", "y_var",
           "nees_mean", "nees_in_band", *evaluate.LATLON)


def _arrow_type(column: str) -> pa.DataType:
    # counts ("n", a window's "area1_n") are integers, every other figure a float
    return pa.int64() if column == "n" or column.endswith("_n") else pa.float64()


SCHEMA = pa.schema([("scenario", pa.string()), ("variant", pa.string()), ("seed", pa.int64()),
                    ("filter", pa.string()), ("status", pa.string()), ("error", pa.string())] +
                   [(m, _arrow_type(m)) for m in METRICS])
#: The figures summarised over seeds, with their table headings.
FIGURES = {"mean": "mean m", "max": "max m", "rms": "RMSE m", "nees_mean": "NEES"}
#: Paper 001 Table 1's rows (statistic -> the per-seed figures it is made of), for the
#: scenarios whose paper gives per-axis variances.
TABLE_1 = {"x error range (m)": ("x_min", "x_max"), "x error variance (m²)": ("x_var",),
           "y error range (m)": ("y_min", "y_max"), "y error variance (m²)": ("y_var",),
           "max error (m)": ("max",), "average error (m)": ("mean",)}


class SweepError(Exception):
    """A sweep that cannot start: one line naming the problem and the fix."""


def scenario_hash(sc: Scenario) -> str:
    return sha256(sc.to_toml().encode("utf-8")).hexdigest()


def default_filters(sc: Scenario) -> tuple[str, ...]:
    """The filters of the scenario's shipped host config."""
    return tuple(emulator_settings(sc.name, {p: dict(v) for p, v in sc.ports.items()})["filters"])


@functools.lru_cache(maxsize=4)
def _scenario(text: str, name: str) -> Scenario:
    # tasks carry the canonical TOML (a Scenario does not pickle); parsed once per worker
    return parse_scenario(tomlfile.parse(text, name), name)


def schema(sc: Scenario) -> pa.Schema:
    """The cells' schema for *sc*: SCHEMA, then the columns its paper's layout adds
    (lab.layouts; a failed cell has them null)."""
    layout = layouts.of(sc.name)
    extra = layout[1].columns(sc) if layout else ()
    return pa.schema(list(SCHEMA) + [(m, _arrow_type(m)) for m in extra])


def seed_cells(sc: Scenario, seed: int, filters: tuple[str, ...],
               duration: float | None) -> list[dict]:
    """The cells of one seed by the byte engine: one in-memory run (:func:`cells`)."""
    estimates, _ = run_in_memory(sc, seed, filters=filters, duration=duration)
    return cells(sc, seed, filters, batch.columns(estimates, filters))


def batch_cells(sc: Scenario, seeds: list[int], filters: tuple[str, ...],
                duration: float | None) -> list[dict]:
    """The cells of *seeds* by the batch engine (lab.batch: :func:`cells` of each)."""
    out = batch.run(sc, seeds, filters=filters, duration=duration)
    return [row for seed, est in zip(seeds, out.estimates) for row in cells(sc, seed, filters, est)]


#: The engines that make a task's cells: name -> fn(scenario, seeds, filters, duration).
ENGINES = {"batch": batch_cells,
           "bytes": lambda sc, seeds, filters, duration: [
               row for seed in seeds for row in seed_cells(sc, seed, filters, duration)]}


def cells(sc: Scenario, seed: int, filters: tuple[str, ...], columns: dict) -> list[dict]:
    """The cells of one seed from its estimates' *columns* (lab.batch.columns): each filter's
    position_errors (with the latitude/longitude figures in the scenario's frame) and the
    figures of its paper's layout (lab.layouts: 004's windows)."""
    tr = truth(sc, seed)
    est = {name: {"t": c["t"], "x": c["x"], "y": c["y"], "vx": c["vx"], "vy": c["vy"],
                  "cov": c["cov"][:, [0, 1, 4, 5]].reshape(-1, 2, 2),
                  "extrapolated": c["extrapolated"]} for name, c in columns.items()}
    errors = evaluate.position_errors(tr, est, frame=sc.frame)
    layout = layouts.of(sc.name)
    columns = layout[1].columns(sc) if layout else ()
    extra = layout[1].figures(sc, tr, est) if layout else {}
    rows = []
    for name in filters:
        e = errors.get(name)
        rows.append(_row(sc.name, seed, name, e | extra.get(name, {}), columns) if e else
                    _failed(sc.name, seed, name, "no estimates inside the truth's time span"))
    return rows


def _row(scenario: str, seed: int, name: str, e: dict, columns: tuple[str, ...] = ()) -> dict:
    """An ok cell: METRICS of *e*, then the layout's *columns* of it."""
    return {"scenario": scenario, "seed": seed, "filter": name, "status": "ok", "error": None,
            **{m: e[m] for m in (*METRICS, *columns)}}


def _failed(scenario: str, seed: int, name: str, error: str) -> dict:
    return {"scenario": scenario, "seed": seed, "filter": name, "status": "failed",
            "error": error, **dict.fromkeys(METRICS)}


def _error_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0]}" if text else type(e).__name__


def run_chunk(text: str, name: str, seeds: list[int], filters: tuple[str, ...],
              duration: float | None, variant: str | None = None,
              engine: str = "bytes") -> list[dict]:
    """One task: the cells of *seeds* (of a parameter sweep's *variant*: its value's label,
    lab.vary) by *engine* (:data:`ENGINES`); if that raises, each seed by the byte engine,
    a seed that raises is run once more, then its cells are failed rows with the error's
    line."""
    sc = _scenario(text, name)
    rows = []
    with shared_truth():  # the task's seeds compute the vehicle's true motion once
        if engine != "bytes":
            try:
                rows = ENGINES[engine](sc, seeds, filters, duration)
                seeds = []
            except Exception:  # noqa: BLE001 - the seeds go the byte engine's way, one by one
                rows = []
        for seed in seeds:
            for attempt in (1, 2):
                try:
                    rows += seed_cells(sc, seed, filters, duration)
                    break
                except Exception as e:  # noqa: BLE001 - any failure of a cell is reported as a row
                    if attempt == 2:
                        rows += [_failed(name, seed, f, _error_line(e)) for f in filters]
    for r in rows:
        r["variant"] = variant
    return rows


def chunk_seeds(seeds: list[int], scenario_s: float, engine: str = "bytes",
                workers: int = 1, batch_size: int = BATCH_SIZE) -> list[list[int]]:
    """*seeds* in tasks: for the byte engine of at least MIN_TASK_VIRTUAL_S of scenario time
    each; for the batch engine batches of at most *batch_size*, a multiple of *workers* of
    them, of equal sizes: each worker the same share (10 000 seeds on 2 workers are 40
    tasks of 250, not 39 of 256 and one of 16, which leaves one worker a task behind)."""
    if engine == "bytes":
        per = max(1, math.ceil(MIN_TASK_VIRTUAL_S / scenario_s))
        return [seeds[i:i + per] for i in range(0, len(seeds), per)]
    workers = max(1, workers)
    tasks = min(len(seeds), math.ceil(math.ceil(len(seeds) / batch_size) / workers) * workers)
    cuts = np.linspace(0, len(seeds), tasks + 1).round().astype(int)  # sizes within one seed
    return [seeds[a:b] for a, b in zip(cuts[:-1], cuts[1:])]


def batch_size_for(memory_bytes: float, scenario_s: float) -> int:
    """The seeds a batch task holds by default: BATCH_SIZE, fewer where a worker's
    *memory_bytes* would not hold them within BATCH_MEMORY_SHARE at BATCH_BYTES_PER_SEED_S
    (at least one)."""
    fits = int(memory_bytes * BATCH_MEMORY_SHARE / (BATCH_BYTES_PER_SEED_S * scenario_s))
    return max(BATCH_SEEDS[0], min(BATCH_SIZE, fits))


def machine_memory() -> int:
    """The memory this machine gives our processes: its physical memory, or its cgroup's
    hard limit where that is lower (v2 or v1; a LocalCluster's share of it is Dask's
    reckoning too on a machine without soft limits or RLIMIT_RSS)."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit():  # "max": none
            total = min(total, int(text))
    return total


def worker_memory(limit: float | None, workers: int) -> float:
    """A worker's memory: its cluster's *limit* (the smallest of its workers', lab.sweep's
    ``_workers``); where none is known (none set, a cluster still to be made, a serial run:
    *workers* 1), this machine's memory shared among *workers*."""
    return limit or machine_memory() / max(1, workers)


@dataclass
class Result:
    """A sweep's rows (requested cells, seed then filter order), what it computed, its output."""
    rows: list[dict]
    filters: tuple[str, ...]
    meta: dict
    tasks: int = 0
    out: Path | None = None
    part: Path | None = field(default=None)


class Client:
    """A dask.distributed client: on the scheduler at *address* (or Dask's own
    ``scheduler-address`` config), with the security of Dask's config, else on a new
    LocalCluster of *workers* processes (default: this machine's cores) with one thread each,
    private to this process (:func:`private_cluster`). A context manager that closes what it
    started."""

    def __init__(self, address: str | None = None, workers: int | None = None) -> None:
        import dask
        from distributed import Client as DaskClient

        address = address or dask.config.get("scheduler-address", None)
        self.cluster = None
        if address:
            try:
                self.client = DaskClient(address, timeout=f"{CONNECT_TIMEOUT_S}s")
            except (OSError, TimeoutError, ValueError) as e:
                raise SweepError(f"scheduler: {address}: no scheduler answered "
                                 f"({_error_line(e)}); start one (dask scheduler) or omit "
                                 "the scheduler for a LocalCluster") from None
        else:
            self.cluster = private_cluster(workers or os.cpu_count() or 1)
            self.client = DaskClient(self.cluster)
        self.address = self.client.scheduler.address

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def private_cluster(workers: int):
    """A LocalCluster of *workers* processes, one thread each, that only this process can use:
    its scheduler, nannies and workers listen on loopback with mutual TLS on credentials made
    for it in memory (``Security.temporary()``), so another local user who connects cannot
    run code as ours (a plain LocalCluster takes any connection to 127.0.0.1)."""
    import logging

    import dask
    from distributed import LocalCluster
    from distributed.security import Security

    import cryptography  # noqa: F401  the sweep extra's; Security.temporary() needs it

    with dask.config.set({ENVIRON: worker_environ(dask.config.get(ENVIRON))}):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            host="127.0.0.1", protocol="tls://", security=Security.temporary(),
                            dashboard_address=None, silence_logs=logging.ERROR)


ENVIRON = "distributed.nanny.pre-spawn-environ"  # what a nanny sets before it starts its worker


def worker_environ(dask_default: dict) -> dict:
    """Dask's environment for its workers without MALLOC_TRIM_THRESHOLD_, which it sets to
    64 kB to hand freed memory back to the system at once. A batch task frees and takes
    again arrays of hundreds of kB at every step, and each time the pages come back as
    page faults: 14 % of a worker's CPU in the kernel (navtwin bench lab-sweep;
    docs/sweeps.md, "The workers' memory"). Unset, glibc's own thresholds, which grow with
    the arrays freed, keep them, as in a plain process; a worker then holds its largest
    task's memory."""
    return {k: v for k, v in dask_default.items() if k != "MALLOC_TRIM_THRESHOLD_"}


def read_out(out: Path) -> tuple[list[dict], list[dict]]:
    """The metadata and rows of every readable part in *out*, oldest first (a part without its
    footer, from a killed run, is skipped: its cells are computed again)."""
    metas, rows = [], []
    for part in sorted(p for p in out.iterdir() if PART.fullmatch(p.name)):
        try:
            f = pq.ParquetFile(part)
            metas.append(json.loads(f.schema_arrow.metadata[META_KEY]))
            rows += f.read().to_pylist()
        except (OSError, KeyError, TypeError, ValueError, pa.ArrowException):
            continue
    return metas, rows


def _check_out(out: Path) -> None:
    """*out* made if missing; refused if it holds anything but a sweep's parts (a recording's
    or the user's files would be mixed with ours, and read as parts)."""
    if out.exists() and not out.is_dir():
        raise SweepError(f"out: {out}: not a directory; pass a directory path")
    try:
        out.mkdir(parents=True, exist_ok=True)
        others = sorted(p.name for p in out.iterdir() if not (PART.fullmatch(p.name)
                                                              and p.is_file()))
    except OSError as e:
        raise SweepError(f"out: {out}: {e.strerror}; choose a writable directory") from None
    if others:
        more = f" and {len(others) - 1} more" if len(others) > 1 else ""
        raise SweepError(f"out: {out}: holds {others[0]}{more}, not only a sweep's "
                         "part-NNNN.parquet files; choose a new or empty directory, or that "
                         "of an earlier sweep")


def _check_same(out: Path, metas: list[dict], meta: dict) -> None:
    for m in metas:
        for key, what in (("scenario_hash", "scenario hash"), ("code_version", "code version"),
                          ("duration_s", "duration"), ("filters", "filter set"),
                          ("vary", "parameter sweep")):
            if m.get(key) != meta[key]:
                raise SweepError(f"out: {out}: holds a sweep of another {what} ({m.get(key)} "
                                 f"there, {meta[key]} now); choose another directory or remove it")


def run(scenario: str | Path | Scenario, seeds: Iterable[int], filters: Iterable[str] | None = None,
        *, duration: float | None = None, out: str | Path | None = None,
        client: Client | None = None, serial: bool = False, vary: Vary | None = None,
        progress: Callable[[int, int], None] | None = None, engine: str = "batch",
        batch_size: int | None = None) -> Result:
    """Sweep *scenario* over *seeds* (and, with *vary*, each of its values: lab.vary): in this
    process if *serial*, else on *client* (a new LocalCluster if None). Rows stream into
    *out*/part-NNNN.parquet when *out* is given, and only the cells *out* lacks are computed.
    *engine*: "batch" (lab.batch: tasks of up to *batch_size* seeds whose tracks step
    together; None: :func:`batch_size_for` a worker's memory) or "bytes" (each seed's
    in-memory run); their cells agree to 1e-9.
    *progress(done, total)* counts (value, seed) runs."""
    if engine not in ENGINES:
        raise SweepError(f"engine {engine!r}: use one of {', '.join(ENGINES)}")
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    seeds = sorted(set(int(s) for s in seeds))
    filters = tuple(filters) if filters else default_filters(sc)
    # each value's scenario made (and checked) before any work
    variants = {None: sc} if vary is None else {
        label(v): variant(sc, vary.key, v) for v in vary.values}
    meta = {"code_version": code_version(), "scenario": sc.name, "scenario_hash": scenario_hash(sc),
            "seeds": [seeds[0], seeds[-1]] if seeds else [], "filters": list(filters),
            "duration_s": duration, "vary": None if vary is None else vary.as_meta(),
            "engine": engine}
    done: dict[tuple[str | None, int, str], dict] = {}
    if out is not None:
        out = Path(out)
        _check_out(out)
        metas, old = read_out(out)
        _check_same(out, metas, meta)
        for r in old:  # a later part's cell replaces an earlier (failed) one
            done[(r["variant"], r["seed"], r["filter"])] = r
    wanted = [(v, s, f) for v in variants for s in seeds for f in filters]
    sized = engine == "batch" and batch_size is None  # a batch size by the workers' memory
    workers, limit = (1, None) if serial else _workers(client, sized)
    memory = worker_memory(limit, workers) if sized else None

    def size(scenario_s: float) -> int:
        return batch_size_for(memory, scenario_s) if sized else batch_size or BATCH_SIZE

    tasks = [(v, chunk) for v, vsc in variants.items() for chunk in chunk_seeds(
        [s for s in seeds if any(done.get((v, s, f), {}).get("status") != "ok" for f in filters)],
        duration or vsc.duration_s, engine, workers, size(duration or vsc.duration_s))]
    texts, cells = {v: vsc.to_toml() for v, vsc in variants.items()}, schema(sc)
    writer = part = None
    if out is not None and tasks:
        n = max([int(m[1]) for p in out.iterdir() if (m := PART.fullmatch(p.name))] + [-1]) + 1
        part = out / f"part-{n:04d}.parquet"
        try:
            writer = pq.ParquetWriter(part, cells.with_metadata({META_KEY: json.dumps(meta)}))
        except OSError as e:
            raise SweepError(f"out: {out}: cannot write {part.name} ({e}); choose a writable "
                             "directory") from None
    total = len(variants) * len(seeds)
    finished = total - sum(len(chunk) for _, chunk in tasks)

    def take(rows: list[dict]) -> None:
        nonlocal finished
        for r in rows:
            done[(r["variant"], r["seed"], r["filter"])] = r
        if writer is not None:
            writer.write_table(pa.Table.from_pylist(rows, schema=cells))
        finished += len({(r["variant"], r["seed"]) for r in rows})
        if progress:
            progress(finished, total)

    if progress:
        progress(finished, total)
    try:
        if serial:
            for v, chunk in tasks:
                take(run_chunk(texts[v], sc.name, chunk, filters, duration, v, engine))
        elif tasks:
            own = client is None
            client = client or Client()
            try:
                _on_dask(client, tasks, texts, sc.name, filters, duration, engine, take)
            finally:
                if own:
                    client.__exit__()
    finally:
        if writer is not None:
            writer.close()
    rows = [done[c] for c in wanted]
    return Result(rows, filters, meta, len(tasks), out, part)


def _workers(client: Client | None, memory: bool = True) -> tuple[int, float | None]:
    """The workers a sweep's batches are shared among, and, if *memory* (a default batch size
    is wanted), the smallest of their memory limits (None: not asked, not known, or not set
    on some): the cluster's (a LocalCluster's to be: the cores, its limits not known yet); 1
    and None when its scheduler does not answer (the watch then says so). The limits are
    asked for once it has answered: a scheduler that is gone would hold the question for
    Dask's reconnect timeout."""
    if client is None:
        return os.cpu_count() or 1, None
    try:
        workers = max(1, len(client.client.ncores(callback_timeout=WATCH_S)))
        limits = [w.get("memory_limit") or 0 for w in
                  client.client.scheduler_info().get("workers", {}).values()] if memory else []
    except (OSError, TimeoutError, RuntimeError):
        return 1, None
    return workers, min(limits) if limits and all(limits) else None


def _on_dask(client: Client, tasks, texts, name, filters, duration, engine, take) -> None:
    from distributed import wait

    n = len(tasks)
    futures = client.client.map(run_chunk, [texts[v] for v, _ in tasks], [name] * n,
                                [chunk for _, chunk in tasks], [filters] * n, [duration] * n,
                                [v for v, _ in tasks], [engine] * n, pure=False, retries=1)
    task_of = {f.key: t for f, t in zip(futures, tasks)}
    pending, watch = set(futures), _Watch(client)
    while pending:
        try:
            done, pending = wait(pending, timeout=WATCH_S, return_when="FIRST_COMPLETED")
        except TimeoutError:  # none done for a while: is the cluster still there?
            watch.check()
            continue
        for f in done:
            if f.status == "finished":
                take(f.result())
            else:  # lost twice (e.g. its worker died): its cells are failed rows
                err, (v, chunk) = _error_line(f.exception()), task_of[f.key]
                take([{**_failed(name, s, flt, err), "variant": v} for s in chunk
                      for flt in filters])
            f.release()


class _Watch:
    """Whether the cluster a sweep waits on can still finish it: its scheduler answers and
    has had workers within NO_WORKERS_S."""

    def __init__(self, client: Client) -> None:
        self.client = client
        self.staffed = time.monotonic()

    def check(self) -> None:
        address = self.client.address
        try:
            # asked of the scheduler now (scheduler_info() is a copy Dask refreshes itself)
            workers = self.client.client.ncores(callback_timeout=WATCH_S)
        except (OSError, TimeoutError, RuntimeError) as e:
            raise SweepError(f"scheduler: {address}: lost during the sweep ({_error_line(e)}); "
                             "the rows done are kept, run the sweep again to finish it") from None
        now = time.monotonic()
        if workers:
            self.staffed = now
        elif now - self.staffed > NO_WORKERS_S:
            raise SweepError(f"scheduler: {address}: no workers for {NO_WORKERS_S:g} s; start "
                             "workers (dask worker ADDRESS) or omit the scheduler for a "
                             "LocalCluster, then run the sweep again")


# ---------------------------------------------------------------- the table over seeds

def summarise(rows: list[dict], filters: Iterable[str], scenario: str | None = None) -> dict:
    """Per filter, over its seeds: the mean of each per-seed figure (FIGURES, TABLE_1's, the
    latitude/longitude ones) with its 95 % t half-width, the seeds and failures; and per pair
    of filters the per-seed difference of mean error (a - b) over the seeds both have, its
    mean, 95 % t half-width, paired t test's p and Holm-adjusted p over every pair, and which
    filter it decides for (the adjusted p below evaluate.ALPHA) or None (evaluate.decide).
    ``ranking``: the filters by mean error, each joined to the next by "<" (decided) or "~"
    (not). For a *scenario* whose paper has a layout of its own (lab.layouts: 003's latitude
    and longitude, 004's areas and outages), that layout's section under its name."""
    filters = tuple(filters)
    ok = {f: {r["seed"]: r for r in rows if r["filter"] == f and r["status"] == "ok"}
          for f in filters}
    per = {}
    for f in filters:
        cells = [ok[f][s] for s in sorted(ok[f])]
        per[f] = {"seeds": len(cells), "failed": sum(1 for r in rows if r["filter"] == f
                                                     and r["status"] != "ok")}
        for m in {**FIGURES, **dict.fromkeys(k for ks in TABLE_1.values() for k in ks),
                  **evaluate.LATLON}:
            per[f][m] = mean_ci([r[m] for r in cells if r.get(m) is not None])
    pairs = [paired(ok, a, b, "mean") for i, a in enumerate(filters) for b in filters[i + 1:]]
    decide(pairs)
    order = sorted((f for f in filters if per[f]["seeds"]), key=lambda f: per[f]["mean"][0])
    ranking = order[:1]
    for a, b in zip(order, order[1:]):
        p = next(p for p in pairs if {p["a"], p["b"]} == {a, b})
        ranking += ["<" if p["better"] else "~", b]
    out = {"filters": per, "pairs": pairs, "ranking": " ".join(ranking)}
    layout = layouts.of(scenario)
    if layout and (section := layout[1].summary(ok, per, scenario)) is not None:
        out[layout[0]] = section
    return out


def summarise_values(rows: list[dict], filters: Iterable[str], scenario: str | None = None) -> dict:
    """A parameter sweep's rows (lab.vary) summarised per value: value label -> :func:`summarise`
    of that value's cells, in the values' order."""
    values = dict.fromkeys(r["variant"] for r in rows)
    return {v: summarise([r for r in rows if r["variant"] == v], filters, scenario)
            for v in values}


def values_table(vary: dict, summaries: dict) -> str:
    """A parameter sweep as text: each value's table under its name, then the mean error of
    every filter at every value side by side (lab.vary.overview)."""
    parts = [f"{vary['key']} = {v}:\n{table(s)}" for v, s in summaries.items()]
    head, rows = overview(vary["key"], summaries)
    return "\n\n".join(parts + [f"mean error (m) by {vary['key']}, ± the 95 % half-width over "
                                 "seeds:\n" + "\n".join(_aligned([head, *rows]))])


def table(summary: dict) -> str:
    """The summary as a text table: figures with 95 % half-widths, then the pairs; columns as
    wide as their widest cell, two spaces apart (a NEES in the thousands stays apart from
    the RMSE before it)."""
    rows = [["filter", "seeds", "failed", *FIGURES.values()]]
    rows += [[f, str(s["seeds"]), str(s["failed"]), *(ci_text(s[m]) for m in FIGURES)]
             for f, s in summary["filters"].items()]
    lines = _aligned(rows)
    lines += ["", f"paired difference of mean error (m, a - b, 95 % CI; Holm p over the "
                  f"{len(summary['pairs'])} pairs, decided below {ALPHA:g}):"]
    pairs = summary["pairs"]
    cells = _aligned([[f"{p['a']} - {p['b']}", ci_text((p["diff"], p["half"]), 4),
                       f"p {p_text(p['holm_p'])}"] for p in pairs]) if pairs else []
    lines += [f"  {c}  {p['better'] + ' better' if p['better'] else 'not decided'}"
              for c, p in zip(cells, pairs)]
    lines.append(f"ranking: {summary['ranking']}")
    for title, head, rows, left in layouts.grids(summary):
        lines += ["", title + ":", *_aligned([head, *rows], left)]
    return "\n".join(lines)


def _aligned(rows: list[list[str]], left: int = 1) -> list[str]:
    """Text rows in columns as wide as their widest cell, two spaces apart, the first *left*
    columns to the left, the others to the right."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) if i < left else c.rjust(w)
                      for i, (c, w) in enumerate(zip(r, widths))).rstrip() for r in rows]


def markdown(summary: dict, scenario: str, meta: dict | None = None) -> str:
    """The summary as Markdown tables, with the published figures of *scenario*'s paper
    (evaluate.PAPER_FIGURES) beside ours; first a line naming the sweep of *meta* (a
    Result's) when given."""
    paper = evaluate.PAPER_FIGURES.get(scenario)
    cols = list(FIGURES.values())
    paper_means = evaluate.has_paper_means(scenario)
    extra = [f"{paper['paper']} mean m", f"{paper['paper']} max m"] if paper_means else []
    lines = []
    if meta:
        a, b = meta["seeds"]
        time = "" if meta["duration_s"] is None else f", first {meta['duration_s']:g} s"
        lines += [f"`{scenario}`, seeds {a}..{b}{time}; navtwin {meta['code_version']}, "
                  f"scenario sha256 {meta['scenario_hash'][:12]}; ± is the 95 % Student-t "
                  f"half-width over seeds; a pair decides where its paired t test's p, "
                  f"Holm-adjusted over the table's pairs, is below {ALPHA:g}.", ""]
    lines += ["| filter | seeds | " + " | ".join(cols + extra) + " |",
             "|---|---:|" + "---:|" * (len(cols) + len(extra))]
    for f, s in summary["filters"].items():
        cells = [ci_text(s[m]) for m in FIGURES]
        if paper_means:
            fig = paper["figures"].get(f, {})
            cells += [_paper(fig.get("mean")), _paper(fig.get("max"))]
        failed = f" ({s['failed']} failed)" if s["failed"] else ""
        lines.append(f"| {f} | {s['seeds']}{failed} | " + " | ".join(cells) + " |")
    lines += ["", "| a - b | seeds | mean error difference m (95 % CI) | Holm p | decides |",
              "|---|---:|---:|---:|---|"]
    for p in summary["pairs"]:
        lines.append(f"| {p['a']} - {p['b']} | {p['seeds']} | {ci_text((p['diff'], p['half']), 4)} "
                     f"| {p_text(p['holm_p'])} | {p['better'] + ' better' if p['better'] else 'not decided'} |")
    lines += _table_1(summary, paper)
    for title, head, rows, left in layouts.grids(summary):
        lines += ["", title + ".", "", "| " + " | ".join(head) + " |",
                  "|" + "---|" * left + "---:|" * (len(head) - left)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
    rank = (f"Ranking by mean error (`<`: the pair is decided, its Holm-adjusted p below "
            f"{ALPHA:g}; `~`: it is not): "
            f"`{summary['ranking']}`")
    means = {f: v["mean"] for f, v in paper["figures"].items() if "mean" in v} if paper else {}
    if means:
        published = sorted(means, key=means.get)
        rank += f"; {paper['paper']}'s by its published means: `{' < '.join(published)}`"
    lines += ["", rank]
    return "\n".join(lines)


def values_markdown(summaries: dict, scenario: str, meta: dict) -> str:
    """A parameter sweep as Markdown: the mean error of every filter at every value side by
    side, then each value's :func:`markdown` under a heading of its own."""
    key = meta["vary"]["key"]
    head, rows = overview(key, summaries)
    lines = [f"Mean error (m) by `{key}`, ± the 95 % half-width over seeds:", "",
             "| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1),
             *("| " + " | ".join(r) + " |" for r in rows)]
    for v, s in summaries.items():
        lines += ["", f"#### `{key}` = {v}", "", markdown(s, scenario, meta)]
    return "\n".join(lines)


def _table_1(summary: dict, paper: dict | None) -> list[str]:
    """Paper 001 Table 1's layout (rows: statistics; columns: the tracks it has figures for,
    ours with 95 % half-widths over seeds, the paper's in parentheses) when *paper* gives
    per-axis variances; [] otherwise."""
    figs = paper["figures"] if paper else {}
    cols = [f for f in figs if "x_var" in figs[f] and f in summary["filters"]]
    if not cols:
        return []
    out = ["", f"Paper {paper['paper']} Table 1's layout: each figure is the mean over seeds of "
           f"that seed's figure, ± its 95 % half-width; ({paper['paper']}'s published figure).", "",
           "| statistic | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
    for label, keys in TABLE_1.items():
        cells = []
        for f in cols:
            s, digits = summary["filters"][f], 4
            cell = " ... ".join(ci_text(s[k], digits) for k in keys)
            pub = figs[f].get({"max": "max", "mean": "mean"}.get(keys[0], keys[0]))
            cells.append(cell + ("" if pub is None else f" ({pub:.4g})"))
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def _paper(v: float | None) -> str:
    return "" if v is None else f"{v:.4g}"

def check_block(path: str | Path) -> None:
    """Refuse, before any work, a *path* that :func:`write_block` could not rewrite: one it
    cannot read as text or open for writing (a read-only file system, a directory, no such
    folder). A missing file is created and removed again to prove its folder takes it."""
    path = Path(path)
    try:
        if path.exists():
            path.read_text(encoding="utf-8")
            with open(path, "r+b"):  # opened for writing, not truncated
                pass
        else:
            with open(path, "xb"):
                pass
            path.unlink()
    except (OSError, UnicodeDecodeError) as e:
        raise _unwritable(path, e) from None


def _unwritable(path: Path, e: OSError | UnicodeDecodeError) -> SweepError:
    if isinstance(e, UnicodeDecodeError):
        return SweepError(f"results: {path}: not UTF-8 text; give a Markdown file such as "
                          "docs/results.md")
    return SweepError(f"results: {path}: {e.strerror or e}; give a file you can write, or "
                      "omit --results")


def write_block(path: str | Path, key: str, text: str) -> None:
    """Put *text* between ``<!-- results:KEY -->`` and ``<!-- /results:KEY -->`` in *path*
    (appended with its markers if they are not there), leaving the rest as written."""
    path = Path(path)
    try:
        doc = path.read_text(encoding="utf-8") if path.exists() else ""
    except (OSError, UnicodeDecodeError) as e:
        raise _unwritable(path, e) from None
    start, end = f"<!-- results:{key} -->", f"<!-- /results:{key} -->"
    block = f"{start}\n{text.rstrip()}\n{end}"
    i, j = doc.find(start), doc.find(end)
    if i >= 0 and j > i:
        doc = doc[:i] + block + doc[j + len(end):]
    else:
        doc = doc.rstrip() + ("\n\n" if doc.strip() else "") + block + "\n"
    try:
        path.write_text(doc, encoding="utf-8")
    except OSError as e:
        raise _unwritable(path, e) from None
