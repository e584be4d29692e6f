"""``navtwin demo``: the live lab in the terminal (rich), then the report and a one-screen table.

The lab is :func:`navtwin.lab.orchestrator.run_lab`'s, with every track on; the view
(``cli/demo_view.py``, imported only here: rich is the ``demo`` extra) draws its
:class:`~navtwin.lab.orchestrator.Watch` state; when stdout is not a terminal (``| tee
lab.log``, CI), ``cli/demo_lines.py`` prints it there as plain lines instead.
"""
from __future__ import annotations

import sys
import threading

from .emulate import SEED_HELP, add_fleet_options, add_follow_option, duration, fleet_kwargs, scenario_help, seed
from .lab import _filter_list, print_report
from .main import UsageError, missing_extra, stop_on_signals

DEFAULT_DURATION_S = 60.0


def register(sub) -> None:
    p = sub.add_parser(
        "demo", help="the emulated lab live in the terminal, with every track, then its report",
        description="Run the emulated lab in real time with the host on its PTYs (as 'navtwin "
        "lab' does) and every fusion track on, and show it live: the scenario's progress, "
        "frames and errors per port, each track's error against the emulator's truth (now, "
        "mean, max) beside the paper's figure, and live faults; with --vehicles N every car's "
        "best track. At the end: the accuracy table (and each car's) and the run directory's "
        "report. Ctrl-C ends the run early and still reports.")
    p.add_argument("--scenario", default="office", metavar="NAME|FILE",
                   help=scenario_help())
    p.add_argument("--duration", type=duration, default=DEFAULT_DURATION_S, metavar="S",
                   help=f"seconds of the scenario to run (default {DEFAULT_DURATION_S:g}; "
                   "at most the scenario's length)")
    p.add_argument("--seed", type=seed, help=SEED_HELP)
    add_fleet_options(p)
    add_follow_option(p)
    p.add_argument("--config", metavar="NAME|FILE",
                   help="the host's config (default: the scenario's lab, e.g. office)")
    p.add_argument("--filters", metavar="LIST", type=_filter_list, default="all",
                   help="the host's --filters (default: all)")
    p.add_argument("--dir", metavar="DIR", help="run directory (default: a new private temp dir)")
    p.add_argument("--json", action="store_true",
                   help="JSON status lines on stderr instead of the live view (as 'navtwin lab')")
    p.set_defaults(func=run, extra="demo")


def run(args) -> int:
    from navtwin.lab.orchestrator import LabError, Watch, run_lab

    if args.json:
        watch = Watch()
    elif not sys.stdout.isatty():
        from .demo_lines import ProgressLines

        watch = ProgressLines()
    else:
        try:
            from .demo_view import LiveView
        except ModuleNotFoundError as e:
            if (line := missing_extra(e, "demo")) is None:
                raise
            raise UsageError(f"{line}, or give --json") from None
        watch = LiveView()
    stop = threading.Event()
    fleet = fleet_kwargs(args)
    try:
        with stop_on_signals(stop), watch:
            report = run_lab(args.scenario, seed=args.seed, duration=args.duration,
                             config=args.config, filters=args.filters, directory=args.dir,
                             stop=stop, watch=watch, **fleet)
    except LabError as e:
        raise UsageError(str(e)) from None
    print_report(report)
    return 0

