"""``python -m navtwin.cli.emulator_bench``: the emulator's benchmarks (:mod:`navtwin.emulator.bench`) with
their own settings, one JSON object on stdout."""
from __future__ import annotations

import argparse
import json
import sys

from navtwin.emulator import bench

from .main import Parser, number


def main(argv: list[str] | None = None) -> int:
    p = Parser(prog="python -m navtwin.cli.emulator_bench", description=bench.__doc__,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="what", required=True, parser_class=Parser)
    repeat = number(1, 1000, integer=True)
    j = sub.add_parser("jitter", help="SINS frame-period jitter on the sins port, real time")
    j.add_argument("--seconds", type=number(1, 3600), default=60.0, help="1 to 3600 (default 60)")
    j.add_argument("--scenario", default="office")
    s = sub.add_parser("speed", help="virtual-time generation speed")
    s.add_argument("--scenario", default="office")
    s.add_argument("--repeat", type=repeat, default=3, help="1 to 1000 (default 3)")
    d = sub.add_parser("digi-open", help="digi-xbee XBeeDevice.open() time on the coordinator")
    d.add_argument("--repeat", type=repeat, default=10, help="1 to 1000 (default 10)")
    r = sub.add_parser("digi-router", help="digi-xbee read_device_info() time on the router")
    r.add_argument("--repeat", type=repeat, default=10, help="1 to 1000 (default 10)")
    args = p.parse_args(argv)
    if args.what == "jitter":
        result = bench.jitter(args.seconds, args.scenario)
    elif args.what == "speed":
        result = bench.speed(args.scenario, repeat=args.repeat)
    elif args.what == "digi-router":
        result = bench.digi_router(args.repeat)
    else:
        result = bench.digi_open(args.repeat)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
