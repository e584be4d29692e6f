"""``navtwin bench``: the benchmark registry, with peers measured in the same run.

Benchmarks come in sets, found in :data:`SETS`: navtwin's own, declared below by
``"module:function"``, then those of installed packages, from the ``navtwin.benchmarks``
entry-point group. A set is a callable returning ``{name: fn}``, where ``fn(quick: bool) ->
dict`` runs one benchmark and returns its figures; the first line of ``fn``'s docstring is its
``--list`` line.
"""
from __future__ import annotations

import json
import sys

from navtwin.protocols.plugins import Registry

from .main import UsageError


#: The benchmark sets: name -> a callable returning {benchmark name: fn}.
SETS = Registry("navtwin.benchmarks", "benchmark set", {
    "decode": "navtwin.protocols.bench:decode_benchmarks",
    "emulator": "navtwin.emulator.bench:benchmarks",
    "host": "navtwin.host.bench:benchmarks",
    "lab": "navtwin.lab.bench:benchmarks",
})


def available() -> dict:
    found = {}
    for _, benchmarks in SETS.items():
        found.update(benchmarks())
    return found


def register(sub) -> None:
    p = sub.add_parser("bench", help="run benchmarks, with peers measured in the same run",
                       description="Run benchmarks and print one JSON object per benchmark. "
                       "Figures are medians; ratios compare with a peer measured in the same run.")
    p.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all); "
                   "--list shows them")
    p.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    p.add_argument("--quick", action="store_true", help="smaller workloads, for a smoke run")
    p.set_defaults(func=run, extra="test")  # the peers benchmarks compare with


def run(args) -> int:
    benches = available()
    if args.list:
        for name, fn in benches.items():
            print(f"{name}\t{(fn.__doc__ or '').strip().splitlines()[0]}")
        return 0
    unknown = [n for n in args.names if n not in benches]
    if unknown:
        raise UsageError(f"unknown benchmark {unknown[0]!r}; choose from {', '.join(benches)}")
    for name in args.names or benches:
        print(f"running {name} ...", file=sys.stderr, flush=True)
        print(json.dumps({"bench": name, **benches[name](args.quick)}), flush=True)
    return 0
