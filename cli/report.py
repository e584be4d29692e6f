"""``navtwin report``: the HTML and Markdown report of a ``navtwin lab`` run directory."""
from __future__ import annotations

from .main import UsageError

DESCRIPTION = """\
Write report.html (one self-contained file: inline SVG plots and style, no network, no script)
and report.md of a run directory of 'navtwin lab --dir DIR': each filter's track over truth and
anchors, error against time with a posterior Cramer-Rao bound, paper 001 Table 1's per-axis
statistics beside the paper's figures, NEES and NIS against their chi-square bands, link and
ranging counters, the faults injected and the run's provenance. Needs matplotlib (the plot
extra)."""


def register(sub) -> None:
    p = sub.add_parser("report", help="write the HTML and Markdown report of a lab run",
                       description=DESCRIPTION)
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run directory of navtwin lab")
    p.add_argument("--out", metavar="DIR", help="where to write them (default: RUN_DIR)")
    p.set_defaults(func=run, extra="plot")


def run(args) -> int:
    import matplotlib  # noqa: F401  the plots: missing, it is refused before any work
    from navtwin.lab.report import ReportError, write_report

    try:
        paths = write_report(args.run_dir, args.out)
    except ReportError as e:
        raise UsageError(str(e)) from None
    print(f"report: {paths['html']}\nsummary: {paths['md']}")
    return 0
