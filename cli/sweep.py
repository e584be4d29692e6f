"""``navtwin sweep``: the arguments of :func:`navtwin.lab.sweep.run`, a progress bar, the table."""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import tempfile
from pathlib import Path

from navtwin.common.limits import BATCH_SEEDS, BATCH_SIZE, SEEDS, span

from .emulate import DURATION_HELP, duration, scenario_help
from .main import UsageError, number

#: Seeds a sweep takes at most (its cells are held in memory).
MAX_SEEDS = 100_000

DESCRIPTION = """\
Monte Carlo sweep: run the scenario once per seed in virtual time (the emulator into the host's
pipeline in memory: no PTY, no file per seed), score each filter against truth, and print per
filter the mean over seeds of its mean, max and RMS error and mean NEES, each with a 95 %
Student-t interval, and the paired per-seed differences of mean error that decide a ranking;
for rssi-centroid also paper 003 Table 1's layout: latitude and longitude error (m) mean, max
and standard deviation per method beside 003's figures, and their paired differences; for
outage-bridging paper 004 Tables 2 and 3's: mean x, y, vx, vy errors in each training area and
each WSN outage beside 004's figures, and Holm-corrected paired differences.
Runs on dask.distributed: by default a LocalCluster of --workers processes that only this sweep
can use (loopback, TLS on temporary credentials), else the scheduler of --scheduler (or of
Dask's config, scheduler-address), with your Dask security config. Any number of workers
gives the same table. One row per (scenario, seed, filter) goes to --out DIR as Parquet; a
re-run into the same DIR computes only the cells it lacks (a DIR holding another scenario,
code version, duration or filter set is refused)."""


def seed_range(text: str) -> range:
    """``A..B`` (both included) or one seed ``N``, each in SEEDS."""
    a, dots, b = text.partition("..")
    seed = number(*SEEDS, integer=True)
    lo = seed(a.strip())
    hi = seed(b.strip()) if dots else lo
    if hi < lo:
        raise argparse.ArgumentTypeError(f"{text}: the range ends before it starts; write A..B "
                                         "with A <= B, e.g. 1..100")
    if hi - lo >= MAX_SEEDS:
        raise argparse.ArgumentTypeError(f"{text}: {hi - lo + 1} seeds; a sweep takes at most "
                                         f"{MAX_SEEDS}, split it into several --out runs")
    return range(lo, hi + 1)


def filter_names(text: str) -> tuple[str, ...]:
    from navtwin.host import tracks

    names = tracks.names()
    if text.strip() == "all":
        return names
    chosen = tuple(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    unknown = [n for n in chosen if n not in names]
    if unknown or not chosen:
        raise argparse.ArgumentTypeError(
            f"{text!r}: {'unknown filter ' + ', '.join(unknown) if unknown else 'no filter given'}"
            f"; give a comma list of {', '.join(names)}, or all")
    return chosen


def _vary(text: str):
    from navtwin.lab.vary import Vary, VaryError

    try:
        return Vary.parse(text)
    except VaryError as e:
        raise argparse.ArgumentTypeError(str(e).removeprefix("vary: ")) from None


def register(sub) -> None:
    p = sub.add_parser("sweep", help="Monte Carlo sweep of a scenario over seeds, on "
                       "dask.distributed, with confidence intervals", description=DESCRIPTION)
    p.add_argument("--scenario", default="office", metavar="NAME|FILE",
                   help=scenario_help())
    p.add_argument("--seeds", required=True, type=seed_range, metavar="A..B",
                   help=f"the seeds, both ends included, each {span(*SEEDS)}, e.g. 1..100")
    p.add_argument("--filters", type=filter_names, metavar="LIST",
                   help="comma list of tracks, or all (default: the scenario's host config's)")
    p.add_argument("--duration", type=duration, metavar="S", help=DURATION_HELP)
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: Dask's "
                            "config scheduler-address, else a LocalCluster)")
    where.add_argument("--workers", type=number(1, 1024, integer=True), metavar="N",
                       help="LocalCluster worker processes, one thread each (default: the cores)")
    where.add_argument("--serial", action="store_true",
                       help="run every seed in this process, without Dask (the same table)")
    p.add_argument("--out", metavar="DIR",
                   help="the Parquet directory (default: a new private temp dir); a re-run into "
                        "it computes only the cells it lacks")
    p.add_argument("--results", metavar="FILE",
                   help="also write the table as Markdown between <!-- results:SCENARIO --> and "
                        "<!-- /results:SCENARIO --> in FILE (e.g. docs/results.md), leaving "
                        "the rest of FILE as it is; for a scenario file SCENARIO is its name "
                        "without .toml")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object (the summary, the output's path and metadata) "
                        "instead of the table")
    p.add_argument("--vary", type=_vary, metavar="KEY=VALUES",
                   help="a parameter sweep: the scenario's KEY (dotted, as in its TOML: "
                        "ranging.sigma0_m, anchors.0.range_bias_m) over VALUES, a comma list "
                        "(0.1,0.3,0.6) or a range A..B:STEP, crossed with the seeds: a table "
                        "per value, then the values side by side (docs/sweeps.md)")
    p.add_argument("--engine", choices=("batch", "bytes"), default="batch",
                   help="batch (default): a task's seeds step their tracks together, the same "
                        "estimates to 1e-9; bytes: each seed's in-memory run (docs/sweeps.md)")
    p.add_argument("--batch-size", type=number(*BATCH_SEEDS, integer=True), metavar="N",
                   help=f"seeds a batch-engine task holds at most (default {BATCH_SIZE}, "
                        "fewer where half a worker's memory would not hold them, at about "
                        "4 MB a seed of office)")
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run, extra="sweep")


def run(args) -> int:
    from navtwin.emulator.scenario import ScenarioError, load_scenario
    from navtwin.lab import sweep
    from navtwin.lab.vary import VaryError

    try:
        sc = load_scenario(args.scenario)
    except ScenarioError as e:
        raise UsageError(str(e)) from None
    if args.duration is not None and args.duration > sc.duration_s:
        raise UsageError(f"--duration {args.duration:g}: longer than {sc.name}'s "
                         f"{sc.duration_s:g} s; give at most that or omit it")
    try:
        if args.results:  # before the work: a file it cannot write would end it at the end
            sweep.check_block(args.results)
        with contextlib.ExitStack() as stack:
            # the cluster first: a scheduler that does not answer is refused before any bar
            client = None if args.serial else stack.enter_context(
                sweep.Client(args.scheduler, args.workers))
            out = args.out or tempfile.mkdtemp(prefix=f"navtwin-sweep-{sc.name}-")
            progress = stack.enter_context(_progress(args.quiet))
            result = sweep.run(sc, args.seeds, args.filters, duration=args.duration, out=out,
                               client=client, serial=args.serial, vary=args.vary,
                               progress=progress, engine=args.engine,
                               batch_size=args.batch_size)
    except (sweep.SweepError, VaryError) as e:
        raise UsageError(str(e)) from None
    vary = result.meta["vary"]
    summary = sweep.summarise(result.rows, result.filters, sc.name) if vary is None \
        else sweep.summarise_values(result.rows, result.filters, sc.name)
    if args.json:
        print(json.dumps(_finite({"summary": summary, "out": str(result.out),
                                  "computed_tasks": result.tasks, "meta": result.meta})))
    else:
        print(sweep.table(summary) if vary is None else sweep.values_table(vary, summary))
        print(f"\nParquet: {result.out} ({result.tasks} tasks computed)")
    if args.results:
        # a scenario file's block is named by the file (a variant of office keeps office's
        # paper and host config but has a table of its own)
        key = Path(args.scenario).stem if args.scenario.endswith(".toml") else sc.name
        text = sweep.markdown(summary, sc.name, result.meta) if vary is None \
            else sweep.values_markdown(summary, sc.name, result.meta)
        try:
            sweep.write_block(args.results, key if vary is None else f"{key}:{vary['key']}",
                              text)
        except sweep.SweepError as e:  # e.g. its file system went read-only during the run
            raise UsageError(f"{e}; the cells are kept in {result.out} (a re-run with that "
                             "--out computes none again)") from None
    return 0


def _finite(obj):
    """*obj* with NaN (an interval of fewer than 2 seeds) as null: JSON has no NaN."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return None if isinstance(obj, float) and math.isnan(obj) else obj


class _progress:
    """A rich progress bar on stderr, as a ``progress(done, total)`` callback."""

    def __init__(self, quiet: bool) -> None:
        self.bar = None
        if not quiet:
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            self.bar = Progress(TextColumn("seeds"), BarColumn(), MofNCompleteColumn(),
                                TimeElapsedColumn(), TimeRemainingColumn(),
                                console=Console(file=sys.stderr))
            self.task = self.bar.add_task("seeds", total=None)

    def __enter__(self):
        return self

    def __call__(self, done: int, total: int) -> None:
        if self.bar is not None:  # started by the first count: after run() has checked --out
            self.bar.start()
            self.bar.update(self.task, completed=done, total=total)

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.stop()
