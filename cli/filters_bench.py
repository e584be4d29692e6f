"""``python -m navtwin.cli.filters_bench``: microseconds per step of each filter
(:mod:`navtwin.host.bench_filters`), as a table or one JSON object."""
from __future__ import annotations

import argparse
import json

from navtwin.host import bench_filters


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m navtwin.cli.filters_bench", description=bench_filters.__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=2000, help="steps per timing run (default 2000)")
    p.add_argument("--json", action="store_true", help="one JSON object instead of a table")
    args = p.parse_args(argv)
    res = bench_filters.measure(args.steps)
    if args.json:
        print(json.dumps(res))
    else:
        for name, us in res.items():
            print(f"{name:14s} {us:8.1f} us/step")
        print(f"estimator: {1e6 / (100 * res['estimator/imu']):.0f}x real time (100 IMU samples/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
