"""``navtwin lab``: the arguments of :func:`navtwin.lab.orchestrator.run_lab`, and its report as a table."""
from __future__ import annotations

import argparse
import threading

from .emulate import DURATION_HELP, SEED_HELP, add_fleet_options, add_follow_option, duration, fleet_kwargs, scenario_help, seed
from .main import UsageError, stop_on_signals


def register(sub) -> None:
    p = sub.add_parser(
        "lab", help="run the emulated lab with the host on it, and report its accuracy",
        description="Start 'navtwin emulate' (real time, recording) and 'navtwin host' on its "
        "PTYs, each as its own process, and when the scenario ends compare the host's estimates "
        "with the emulator's truth.csv: mean and max position error per filter beside paper "
        "000's figures, and a plot. With --vehicles N, one host follows the cars on a shared "
        "air, or one host per car with --network per-vehicle, and every car is scored against "
        "its own truth. Ctrl-C ends the run early and still reports.")
    p.add_argument("--scenario", default="office", metavar="NAME|FILE",
                   help=scenario_help())
    p.add_argument("--seed", type=seed, help=SEED_HELP)
    p.add_argument("--duration", type=duration, metavar="S", help=DURATION_HELP)
    add_fleet_options(p)
    add_follow_option(p)
    p.add_argument("--config", metavar="NAME|FILE",
                   help="the host's config (default: the scenario's lab, e.g. office); with "
                        "--vehicles each car is its vehicle 1 with the car's tag and router")
    p.add_argument("--filters", metavar="LIST", type=_filter_list,
                   help="the host's --filters, which checks the names (default: its config's)")
    p.add_argument("--dir", metavar="DIR", help="run directory (default: a new private temp dir)")
    p.add_argument("--no-plot", dest="plot", action="store_false",
                   help="skip report.png and report.html/.md")
    p.set_defaults(func=run)


def _filter_list(text: str) -> str:
    """Refuse an empty list here, before anything starts; the host judges the names."""
    if not text.replace(",", "").strip():
        raise argparse.ArgumentTypeError(f"{text!r}: no filter given; give a comma list of "
                                         "the host's filters, or all")
    return text


def run(args) -> int:
    from navtwin.lab.orchestrator import LabError, run_lab

    stop = threading.Event()
    fleet = fleet_kwargs(args)
    try:
        with stop_on_signals(stop):
            report = run_lab(args.scenario, seed=args.seed, duration=args.duration,
                             config=args.config, filters=args.filters, directory=args.dir,
                             stop=stop, plot=args.plot, **fleet)
    except LabError as e:
        raise UsageError(str(e)) from None
    print_report(report)
    return 0


def print_report(report: dict) -> None:
    """The end of a lab run on stdout: the accuracy table, the audit, where the files are."""
    from navtwin.lab import evaluate
    from navtwin.lab.audit import report as audit_report

    if "car" in report:  # the main figures are of the first car the hosts followed
        print(f"car {report['car']}:")
    print(evaluate.table(report["errors"], report["emulator"].get("scenario"))
          if report["errors"] else "no estimates to compare")
    if report.get("vehicles"):
        print("\n" + evaluate.vehicles_table({int(v): r["errors"] for v, r in report["vehicles"].items()}))
    if "audit" in report:  # the scenario injected faults
        a = report["audit"]
        print("\naudit of the host against the fault ledger:\n" +
              (audit_report(a) if "ports" in a else f"not possible: {a['error']}"), end="")
    print(f"\nrun directory: {report['dir']}" + (f"\nplot: {report['plot']}" if report.get("plot")
                                                  else "") +
          (f"\nreport: {report['html']}" if report.get("html") else ""))
