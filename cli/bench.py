"""``navtwin bench``: the benchmark registry, with peers measured in the same run.

Benchmarks come in sets, found in :data:`SETS`: navtwin's own, declared below by
``"module:function"``, then those of installed packages, from the ``navtwin.benchmarks``
entry-point group. A set is a callable returning ``{name: fn}``, where ``fn(quick: bool) ->
dict`` runs one benchmark and returns its figures; the first line of ``fn``'s docstring is its
``--list`` line. A benchmark with settings declares them once, as a table class of
``common.schema.key`` fields (``@takes(Settings)``): ``navtwin bench NAME --setting value``
(``--help`` after NAME lists them) builds and checks them as a TOML table is checked, and
calls ``fn(quick, settings)``. A benchmark whose live lab run fails (the emulator or the
host died) raises :class:`navtwin.lab.orchestrator.LabError`: one line, exit status 2.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import typing

from navtwin.protocols.plugins import Registry

from .main import UsageError, flag

#: The benchmark sets: name -> a callable returning {benchmark name: fn}.
SETS = Registry("navtwin.benchmarks", "benchmark set", {
    "decode": "navtwin.protocols.bench:decode_benchmarks",
    "emulator": "navtwin.emulator.bench:benchmarks",
    "scale": "navtwin.emulator.bench_scale:benchmarks",
    "writes": "navtwin.emulator.bench_writes:benchmarks",
    "host": "navtwin.host.bench:benchmarks",
    "batch": "navtwin.host.batch.bench:benchmarks",
    "lab": "navtwin.lab.bench:benchmarks",
    "sweep": "navtwin.lab.bench_sweep:benchmarks",
})
#: where a setting's value waits in the parsed arguments (apart from bench's own options)
_DEST = "setting_"


def available() -> dict:
    found = {}
    for _, benchmarks in SETS.items():
        found.update(benchmarks())
    return found


def register(sub) -> None:
    p = sub.add_parser("bench", help="run benchmarks, with peers measured in the same run",
                       description="Run benchmarks and print one JSON object per benchmark. "
                       "Figures are medians; ratios compare with a peer measured in the same run.",
                       epilog="A benchmark's settings follow its name: navtwin bench NAME "
                       "--setting value; 'navtwin bench NAME --help' lists them.",
                       options_for=_settings_options)
    p.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all); "
                   "--list shows them")
    p.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    p.add_argument("--quick", action="store_true", help="smaller workloads, for a smoke run")
    p.set_defaults(func=run, extra="test")  # the peers benchmarks compare with


def _settings_options(parser, args: list[str]) -> None:
    """The options of the one benchmark named first (``navtwin bench NAME --seconds 60``)."""
    names = []
    for a in args:
        if a.startswith("-"):
            break
        names.append(a)
    if len(names) != 1:
        return
    try:
        fn = available().get(names[0])
    except ModuleNotFoundError:  # the test extra is missing; run() names it
        return
    cls = getattr(fn, "Settings", None)
    if cls is None:
        return
    fields = [f for f in dataclasses.fields(cls) if flag(f.name) not in parser._option_string_actions]
    if not fields:
        return
    group = parser.add_argument_group(f"settings of {names[0]}")
    hints = typing.get_type_hints(cls)
    for f in fields:
        meta = f.metadata
        what, _, default = meta.get("doc", "").partition(";")  # "meaning; none = default"
        valid = [c.must.replace("must be ", "") for c in meta.get("checks", ())]
        detail = ", ".join(x for x in (meta.get("unit", ""), *valid) if x)
        text = what + (f" ({detail})" if detail else "") + (f";{default}" if default else "")
        if hints[f.name] is bool:
            group.add_argument(flag(f.name), dest=_DEST + f.name, action="store_true",
                               default=argparse.SUPPRESS, help=text)
        else:
            group.add_argument(flag(f.name), dest=_DEST + f.name, default=argparse.SUPPRESS,
                               metavar=f.name.upper(), help=text)


def settings(name: str, cls, given: dict):
    """Benchmark *name*'s settings *cls* from the command line's *given* texts (setting ->
    text, or True for a switch); UsageError (one line naming the flag) if one is not valid."""
    from navtwin.common.schema import Invalid, build

    hints = typing.get_type_hints(cls)
    values = {}
    for key, text in given.items():
        if key not in hints:
            raise UsageError(f"{name} takes no {flag(key)}; its settings: "
                             f"{', '.join(map(flag, hints))}")
        tp = next((a for a in typing.get_args(hints[key]) if a is not type(None)), hints[key])
        try:
            values[key] = tp(text) if tp in (int, float) else text
        except ValueError:
            values[key] = text  # the schema names what it should be
    try:
        return build(cls, values)
    except Invalid as e:
        raise UsageError(f"{flag(e.where)} {e.problem}") from None


def run(args) -> int:
    benches = available()
    if args.list:
        for name, fn in benches.items():
            print(f"{name}\t{(fn.__doc__ or '').strip().splitlines()[0]}")
        return 0
    unknown = [n for n in args.names if n not in benches]
    if unknown:
        raise UsageError(f"unknown benchmark {unknown[0]!r}; choose from {', '.join(benches)}")
    given = {k[len(_DEST):]: v for k, v in vars(args).items() if k.startswith(_DEST)}
    runs = [(name, benches[name], getattr(benches[name], "Settings", None))
            for name in args.names or benches]
    runs = [(name, fn, cls and settings(name, cls, given)) for name, fn, cls in runs]  # all checked first
    from navtwin.lab.orchestrator import LabError

    for name, fn, s in runs:
        print(f"running {name} ...", file=sys.stderr, flush=True)
        try:
            result = fn(args.quick) if s is None else fn(args.quick, s)
        except LabError as e:  # a side of a live lab run failed: its one line
            raise UsageError(f"{name} failed: {e}") from None
        print(json.dumps({"bench": name, **result}), flush=True)
    return 0
