"""``navtwin emulate``: run a scenario on pseudo-terminals, optionally recording it."""
from __future__ import annotations

import json
import signal
import sys
import threading
from pathlib import Path

from protocols.cli import UsageError, stop_on_signals

DESCRIPTION = """\
Run the emulated lab: the SINS board, the lab computer's XBee coordinator (API mode) and the
nanoLOC gateway, each on a pseudo-terminal with a stable link (DIR/sins, DIR/xbee,
DIR/nanoloc). On start it prints one JSON line {"ready": true, "ports": {...}, "pts": {...},
...} on stdout; it runs until the duration ends or SIGINT/SIGTERM, removes its links and
prints a final {"done": true, ...} line with frames, bytes and drop counts per port.
Progress goes to stderr every few seconds."""


def register(sub) -> None:
    p = sub.add_parser("emulate", help="run a scenario on pseudo-terminals",
                       description=DESCRIPTION)
    p.add_argument("--scenario", required=True, metavar="NAME|FILE",
                   help="a shipped scenario name (e.g. office, corridor-outage) or a .toml file")
    p.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="seconds of scenario time to run (default: the whole scenario)")
    p.add_argument("--speed", default="realtime", metavar="realtime|max|FACTOR",
                   help="realtime (default) keeps the devices' absolute schedule on the wall "
                        "clock; a FACTOR runs it that many times faster; max as fast as possible. "
                        "The bytes are the same at every speed")
    p.add_argument("--link-dir", metavar="DIR",
                   help="directory for the port links, created 0700 (default: "
                        "$XDG_RUNTIME_DIR/navtwin or /tmp/navtwin-UID)")
    p.add_argument("--record", metavar="DIR",
                   help="write a recording: DIR/recording.json, <port>.bin and <port>.csv per "
                        "port, scenario.toml and truth.csv (not through a symbolic link; "
                        "flushed every 0.5 s, so a killed run leaves a replayable prefix)")
    p.add_argument("--overwrite", action="store_true",
                   help="with --record: replace the recording already in DIR")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run_emulate)


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
    from .pty import LinkDirError
    from .runner import Emulation, RunError, parse_speed
    from .scenario import ScenarioError, load_scenario

    try:
        speed = parse_speed(args.speed)
        if args.record is not None:
            _check_record_dir(args.record, args.overwrite)
        scenario = load_scenario(args.scenario)
    except (RunError, ScenarioError) as e:
        raise UsageError(str(e)) from None
    progress = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    stop = threading.Event()
    try:
        emu = Emulation(scenario, args.seed, speed=speed, duration_s=args.duration,
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
