"""``navtwin emulate``: run a scenario on pseudo-terminals, optionally recording it."""
from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

from navtwin.common.limits import MAX_DURATION_S, SEEDS, SPEEDS, span

from .main import UsageError, number, stop_on_signals

#: --seed and --duration, shared with ``navtwin lab``.
seed = number(*SEEDS, integer=True)
SEED_HELP = f"random seed {span(*SEEDS)} (default: the scenario's)"
duration = number(0, MAX_DURATION_S, above=True)
DURATION_HELP = "seconds of scenario time to run, at most the scenario's length (default: all of it)"

DESCRIPTION = """\
Run the emulated lab: the SINS board, the lab computer's XBee coordinator (API mode) and the
nanoLOC gateway, each on a pseudo-terminal with a stable link (DIR/sins, DIR/xbee,
DIR/nanoloc). On start it prints one JSON line {"ready": true, "ports": {...}, "pts": {...},
...} on stdout; it runs until the duration ends or SIGINT/SIGTERM, removes its links and
prints a final {"done": true, ...} line with frames, bytes and drop counts per port, and
per fault kind the injections and bytes touched (the recording's faults.jsonl lists each).
Progress goes to stderr every few seconds. While it runs, `navtwin ctl` (DIR/control)
injects faults, unplugs and replugs ports."""


def register(sub) -> None:
    p = sub.add_parser("emulate", help="run a scenario on pseudo-terminals",
                       description=DESCRIPTION)
    p.add_argument("--scenario", required=True, metavar="NAME|FILE",
                   help="a shipped scenario name (e.g. office, corridor-outage) or a .toml file")
    p.add_argument("--seed", type=seed, help=SEED_HELP)
    p.add_argument("--duration", type=duration, metavar="S", help=DURATION_HELP)
    p.add_argument("--speed", default="realtime", type=_speed, metavar="realtime|max|FACTOR",
                   help="realtime (default) keeps the devices' absolute schedule on the wall "
                        f"clock; a FACTOR {span(*SPEEDS)} runs it that many times faster; max "
                        "as fast as possible. The bytes are the same at every speed")
    p.add_argument("--link-dir", metavar="DIR",
                   help="directory for the port links, created 0700 (default: "
                        "$XDG_RUNTIME_DIR/navtwin or /tmp/navtwin-UID)")
    p.add_argument("--record", metavar="DIR",
                   help="write a recording: DIR/recording.json, <port>.bin and <port>.csv per "
                        "port, scenario.toml and truth.csv (not through a symbolic link; "
                        "flushed every 0.5 s, so a killed run leaves a replayable prefix)")
    p.add_argument("--overwrite", action="store_true",
                   help="with --record: replace the recording already in DIR")
    p.add_argument("--fault", action="append", default=[], metavar="KIND:KEY=VALUE,...",
                   help="add a fault to the scenario's [[faults]] (repeatable), e.g. "
                        "byte_drop:port=sins,probability=0.01,start_s=0,end_s=5; keys and "
                        "checks as in [[faults]] (docs/scenarios.md), values as TOML scalars")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run_emulate)


def _speed(text: str) -> float | None:
    from navtwin.emulator.runner import RunError, parse_speed

    try:
        return parse_speed(text)
    except RunError as e:
        raise argparse.ArgumentTypeError(str(e).removeprefix("speed: ")) from None


def _check_record_dir(path: str, overwrite: bool) -> None:
    d = Path(path)
    if d.is_symlink():
        return  # the recording writer refuses it, and says why
    if d.exists() and not d.is_dir():
        raise UsageError(f"--record {path}: not a directory; pass a directory path")
    if d.is_dir() and any(d.iterdir()):
        if not overwrite:
            raise UsageError(f"--record {path}: directory is not empty; pass --overwrite to "
                             f"replace a recording there, or choose another directory")
        if not (d / "recording.json").is_file():
            raise UsageError(f"--record {path}: not empty and not a navtwin recording; "
                             f"choose another directory")


def run_emulate(args) -> int:
    from navtwin.emulator.pty import LinkDirError
    from navtwin.emulator.runner import Emulation, RunError
    from navtwin.emulator.scenario import ScenarioError, load_scenario, with_faults

    try:
        if args.record is not None:
            _check_record_dir(args.record, args.overwrite)
        scenario = with_faults(load_scenario(args.scenario), args.fault)
    except (RunError, ScenarioError) as e:
        raise UsageError(str(e)) from None
    progress = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    stop = threading.Event()
    try:
        emu = Emulation(scenario, args.seed, speed=args.speed, duration_s=args.duration,
                        link_dir=args.link_dir, record=args.record, progress=progress)
    except (LinkDirError, RunError) as e:
        raise UsageError(str(e)) from None
    # stop cleanly, links removed, on Ctrl-C, kill and a closed terminal
    with emu, stop_on_signals(stop, (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)):
        _emit(emu.info())
        summary = emu.run(stop)
    if emu.record_error is not None:  # the run ended there; the recording is closed
        summary["recording_error"] = str(emu.record_error)
    _emit(summary)  # after close: the recording is complete when "done" appears
    if emu.record_error is not None:
        raise UsageError(f"--record {emu.record_error}")
    return 0


def _emit(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj, separators=(",", ":")) + "\n")
    sys.stdout.flush()
