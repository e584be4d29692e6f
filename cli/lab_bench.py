"""``python -m navtwin.cli.lab_bench``: the lab's benchmarks (:mod:`navtwin.lab.bench`) with their own
settings, one JSON object on stdout."""
from __future__ import annotations

import argparse
import json
import sys

from navtwin.host import config as host_config
from navtwin.host import tracks
from navtwin.host.bench import bench_replay
from navtwin.lab import bench
from navtwin.lab.bench import in_memory, latency, office_replay

from .main import Parser, number


def _filters(text: str) -> tuple[str, ...]:
    try:
        return host_config.parse_filters(text)
    except host_config.ConfigError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def main(argv: list[str] | None = None) -> int:
    p = Parser(prog="python -m navtwin.cli.lab_bench", description=bench.__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="what", required=True, parser_class=Parser)
    filters = {"type": _filters, "default": tracks.DEFAULT,
               "help": "comma list or all (default: 000's sins,wsn,kf,ekf,ukf)"}
    lat = sub.add_parser("latency", help="the host on PTYs: last byte -> estimate line")
    lat.add_argument("--seconds", type=number(1, 3600), default=20.0, help="1 to 3600 (default 20)")
    lat.add_argument("--filters", **filters)
    rep = sub.add_parser("replay", help="replay speed of a recording")
    rep.add_argument("directory", nargs="?", help="a host or emulator recording "
                     "(default: a host recording of the office lab)")
    rep.add_argument("--seconds", type=number(1, 3600), default=60.0,
                     help="length of the default recording, 1 to 3600 (default 60)")
    rep.add_argument("--filters", **filters)
    rep.add_argument("--runs", type=number(1, 100, integer=True), default=5,
                     help="replays, their median wall time counts, 1 to 100 (default 5)")
    mem = sub.add_parser("in-memory", help="seeds/s in memory vs recorded and replayed")
    mem.add_argument("--scenario", default="office")
    mem.add_argument("--seeds", type=number(1, 1000, integer=True), default=3,
                     help="1 to 1000 (default 3)")
    k = sub.add_parser("soak", help="live soak: second reader, emulator restart, memory")
    k.add_argument("--seconds", type=number(30, 36000), default=600.0,
                   help="30 to 36000 (default 600)")
    k.add_argument("--dir", help="keep the run here (default: a new temp dir)")
    k.add_argument("--faults", action="store_true",
                   help="inject lab.soak.SOAK_FAULTS periodically, record the host and audit it "
                        "(no emulator restart then)")
    sw = sub.add_parser("sweep", help="seeds/s of navtwin sweep, serial and on a LocalCluster")
    sw.add_argument("--scenario", default="office")
    sw.add_argument("--seeds", type=number(1, 1000, integer=True), default=8,
                    help="1 to 1000 (default 8)")
    sw.add_argument("--workers", type=number(1, 64, integer=True), default=2,
                    help="LocalCluster workers, 1 to 64 (default 2)")
    sw.add_argument("--duration", type=number(0, 3600, above=True),
                    help="seconds of each run (default: the whole scenario)")
    args = p.parse_args(argv)
    if args.what == "latency":
        result = latency(args.seconds, args.filters)
    elif args.what == "replay":
        result = (bench_replay(args.directory, args.filters, args.runs) if args.directory
                  else office_replay(args.seconds, args.filters, runs=args.runs))
    elif args.what == "in-memory":
        result = in_memory(args.scenario, args.seeds)
    elif args.what == "sweep":
        result = bench.sweep_rate(args.scenario, args.seeds, args.workers, args.duration)
    else:
        from navtwin.lab.soak import soak

        result = soak(args.seconds, directory=args.dir, faults=args.faults,
                      progress=lambda m: print(m, file=sys.stderr, flush=True))
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
