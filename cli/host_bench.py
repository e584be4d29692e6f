"""``python -m cli.host_bench``: the host's benchmarks (:mod:`host.bench`) with their own
settings, one JSON object on stdout."""
from __future__ import annotations

import argparse
import json
import sys

from host import bench
from host import config as host_config


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m cli.host_bench", description=bench.__doc__.split("\n\n")[0])
    p.add_argument("which", choices=("latency", "replay"))
    p.add_argument("directory", nargs="?", help="replay: a recording (default: synthetic)")
    p.add_argument("--seconds", type=float, help="synthetic lab length (latency 20, replay 60)")
    p.add_argument("--filters", default="all", help="comma list or all (default all)")
    p.add_argument("--config", default=None, help="host config (default office)")
    args = p.parse_args(argv)
    cfg = host_config.load(args.config)
    filters = host_config.parse_filters(args.filters)
    if args.which == "latency":
        result = bench.bench_latency(cfg, filters, args.seconds or 20.0)
    else:
        result = bench.bench_replay(cfg, filters, args.seconds or 60.0, args.directory)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
