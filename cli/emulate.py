"""``navtwin emulate``: run a scenario on pseudo-terminals, optionally recording it."""
from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import threading
from pathlib import Path

from navtwin.common.limits import MAX_DURATION_S, NETWORKS, SEEDS, SPEEDS, VEHICLES, span
from navtwin.emulator.timing import NAMES as TIMINGS

MAX_VEHICLES = VEHICLES[1]
MAX_WORKERS = 64  # processes; more than cores only slows the schedule down
from .main import UsageError, flagged, number, stop_on_signals

def scenario_help() -> str:
    """--scenario's help: the shipped names (emulator.shipped: the CLI starts fast)."""
    from navtwin.emulator.shipped import NAMES

    return f"a shipped scenario ({', '.join(NAMES)}) or a TOML file"


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
prints a final {"done": true, ...} line with frames, bytes and drop counts per port (and in a
paced run how late its writes were, "late"), and per fault kind the injections and bytes
touched (the recording's faults.jsonl lists each).
Progress goes to stderr every few seconds. While it runs, `navtwin ctl` (DIR/control)
injects faults, unplugs and replugs ports.

For shell CI, --expect PORT:PATTERN (repeatable) waits for each pattern on its port, in the
order given per port, and stops the run with status 0 once all have come; --fail-on
PORT:PATTERN fails the run as soon as it comes (until the expects are all seen, or the
--timeout, or the end of the run). PATTERN: hex:7E0005 (bytes), re:REGEX (a regex on the raw
stream, its text as Latin-1 bytes), or FIELD=VALUE,... (a decoded frame whose fields equal
those values, integers in any base: type=0x88,command=AP,status=0). --timeout S bounds the
wait, in device time at --speed max or a FACTOR. Exit status 3: an expect timed out (or the
run ended first) or a fail-on came; the message names it, with the port's last frames."""

def add_fleet_options(p) -> None:
    """--vehicles and --network, shared with ``navtwin lab`` and ``navtwin demo``."""
    p.add_argument("--vehicles", type=number(1, MAX_VEHICLES, integer=True), metavar="N",
                   help="run N cars: the scenario's vehicle and N - 1 copies in a queue on its "
                        "line, each with its own tag id, router address and ports (sins2, "
                        "...) (emulator.fleet; docs/scenarios.md, Vehicles)")
    p.add_argument("--network", choices=NETWORKS,
                   help="with --vehicles: shared = one coordinator (xbee) and one anchors' TDMA "
                        "for every car (the scenario's default); per-vehicle = a coordinator, "
                        "nanoLOC network and ports (xbee2, nanoloc2, ...) per car")


def fleet_kwargs(args) -> dict:
    """``vehicles`` and ``network`` of --vehicles and --network (UsageError: --network alone),
    and ``follow`` of ``navtwin lab`` and ``demo``'s --follow."""
    if args.vehicles is None and args.network is not None:
        raise UsageError("--network says how --vehicles share the air; pass --vehicles N")
    out = {"vehicles": args.vehicles, "network": args.network}
    if getattr(args, "follow", None) is not None:
        out["follow"] = args.follow
    return out


def _cars(text: str) -> tuple[int, ...]:
    """--follow's comma list of car numbers."""
    try:
        cars = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: write car numbers separated by commas, "
                                         "e.g. 1,3") from None
    return cars


def add_follow_option(p) -> None:
    """--follow of ``navtwin lab`` and ``demo``: the hosts follow only these cars."""
    p.add_argument("--follow", type=_cars, metavar="LIST",
                   help="the hosts follow only these cars (e.g. 2,3; default all): one host for "
                        "those on a shared air, one each on their own ports (lab/fleet.py)")


def fleet_scenario(scenario, args):
    """*scenario* with --vehicles and --network applied (ScenarioError if it cannot be)."""
    from navtwin.emulator.fleet import convoy

    kw = fleet_kwargs(args)
    return scenario if kw["vehicles"] is None else convoy(scenario, kw["vehicles"], network=kw["network"])


#: exit status of a failed --expect / --fail-on (2 stays bad input, like Wokwi CI's own code)
EXPECT_FAILED = 3


def register(sub) -> None:
    p = sub.add_parser("emulate", help="run a scenario on pseudo-terminals",
                       description=DESCRIPTION)
    p.add_argument("--scenario", required=True, metavar="NAME|FILE", help=scenario_help())
    p.add_argument("--seed", type=seed, help=SEED_HELP)
    p.add_argument("--duration", type=duration, metavar="S", help=DURATION_HELP)
    add_fleet_options(p)
    p.add_argument("--speed", default="realtime", type=_speed, metavar="realtime|max|FACTOR",
                   help="realtime (default) keeps the devices' absolute schedule on the wall "
                        f"clock; a FACTOR {span(*SPEEDS)} runs it that many times faster; max "
                        "as fast as possible. The bytes are the same at every speed")
    p.add_argument("--timing", default="auto", choices=TIMINGS,
                   help="how a paced run waits for its deadlines: fifo (SCHED_FIFO real-time "
                        "priority and 1 ns timer slack), slack (1 ns timer slack), spin (neither; "
                        "a longer busy-wait); auto (default) the first of these the process may "
                        "use. The ready and done lines and the recording name it (\"timing\"); "
                        "the done line and the recording count, per port, how late its writes "
                        "were (docs/emulator.md, Timing)")
    p.add_argument("--link-dir", metavar="DIR",
                   help="directory for the port links, created 0700 (default: "
                        "$XDG_RUNTIME_DIR/navtwin or /tmp/navtwin-UID)")
    p.add_argument("--record", metavar="DIR",
                   help="write a recording: DIR/recording.json, <port>.bin and <port>.csv per "
                        "port, air.bin and air.csv (the radio hop's IEEE 802.15.4 frames), "
                        "scenario.toml and truth.csv (not through a symbolic link; "
                        "flushed every 0.5 s, so a killed run leaves a replayable prefix)")
    p.add_argument("--overwrite", action="store_true",
                   help="with --record: replace the recording already in DIR")
    p.add_argument("--fault", action="append", default=[], metavar="KIND:KEY=VALUE,...",
                   help="add a fault to the scenario's [[faults]] (repeatable), e.g. "
                        "byte_drop:port=sins,probability=0.01,start_s=0,end_s=5; keys and "
                        "checks as in [[faults]] (docs/scenarios.md), values as TOML scalars")
    p.add_argument("--expect", action="append", default=[], type=_check_arg,
                   metavar="PORT:PATTERN",
                   help="wait for PATTERN on PORT (repeatable; in order per port); the run "
                        "stops with status 0 once every expect came, status 3 if one did not "
                        "within --timeout or the run")
    p.add_argument("--fail-on", action="append", default=[], type=_check_arg,
                   metavar="PORT:PATTERN",
                   help="status 3 as soon as PATTERN comes on PORT (repeatable)")
    p.add_argument("--timeout", type=number(0, MAX_DURATION_S, above=True), metavar="S",
                   help="with --expect/--fail-on: seconds (device time in virtual time) to "
                        "wait; --fail-on alone passes once they are over")
    p.add_argument("--rfc2217", metavar="[HOST:]PORT",
                   help="also serve every port as an RFC 2217 server (pyserial rfc2217://, "
                        "ser2net-style clients, navtwin host), one TCP port each from PORT in "
                        "the lab's port order, on loopback unless HOST is given; the ready "
                        "line lists them under \"rfc2217\". The baud and stop bits the client "
                        "sets are the device's view of it, as on the PTY")
    p.add_argument("--workers", default="1", type=_workers, metavar="K|auto",
                   help="run the vehicles in K worker processes on one clock (vehicle n in "
                        "worker (n - 1) mod K), when one process cannot keep their schedule; "
                        "auto: from the cost of one vehicle measured at start-up, at most the "
                        "CPU count. Needs --network per-vehicle; the ready line says how many "
                        "(\"workers\"); no --record, --expect or control socket with K > 1 "
                        "(docs/emulator.md, The loop and worker processes)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run_emulate)


def _speed(text: str) -> float | None:
    from navtwin.emulator.runner import RunError, parse_speed

    try:
        return parse_speed(text)
    except RunError as e:
        raise argparse.ArgumentTypeError(str(e).removeprefix("speed: ")) from None


def _workers(text: str) -> str | int:
    if text == "auto":
        return text
    try:
        k = int(text)
    except ValueError:
        k = 0
    if not 1 <= k <= MAX_WORKERS:
        raise argparse.ArgumentTypeError(f"{text!r}: give auto or a count 1..{MAX_WORKERS}")
    return k


def _check_arg(text: str):
    """PORT:PATTERN -> (port, protocols.match.Match)."""
    from navtwin.protocols import ports
    from navtwin.protocols.match import parse

    port, colon, pattern = text.partition(":")
    if not colon or not ports.known(port):
        raise argparse.ArgumentTypeError(f"{text!r}: write PORT:PATTERN with PORT one of "
                                         f"{', '.join(ports.names())} (vehicle n's: sins2, ...)")
    try:
        return port, parse(pattern)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


class _ThisRun:
    """The running emulation as emulator.expect sees a lab: its ports, speed and clock."""

    def __init__(self, info: dict, ended: threading.Event) -> None:
        from navtwin.emulator.control import Control

        self.info, self.ports, self._ended = info, info["ports"], ended
        self.status = Control(info["link_dir"]).status

    def running(self) -> bool:
        return not self._ended.is_set()


@contextlib.contextmanager
def _rfc2217(address: str | None, links: dict[str, str]):
    """The RFC 2217 servers of --rfc2217 (None without it), closed with the run."""
    if address is None:
        yield None
        return
    from navtwin.emulator.rfc2217 import Rfc2217Error, Rfc2217Servers, parse_address

    try:
        servers = Rfc2217Servers(dict(links), *parse_address(address))
    except Rfc2217Error as e:
        raise UsageError(flagged(str(e))) from None
    try:
        yield servers
    finally:
        servers.close()


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
        scenario = with_faults(fleet_scenario(load_scenario(args.scenario), args), args.fault)
    except (RunError, ScenarioError) as e:
        raise UsageError(str(e)) from None
    workers, chosen = _worker_count(args, scenario)
    if workers > 1:
        return _run_workers(args, scenario, workers, chosen)
    progress = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    stop = threading.Event()
    try:
        emu = Emulation(scenario, args.seed, speed=args.speed, duration_s=args.duration,
                        link_dir=args.link_dir, record=args.record, timing=args.timing,
                        progress=progress)
    except (LinkDirError, RunError) as e:
        raise UsageError(flagged(str(e))) from None  # "timing: ..." -> "--timing ..."
    # stop cleanly, links removed, on Ctrl-C, kill and a closed terminal
    if args.timeout is not None and not (args.expect or args.fail_on):
        raise UsageError("--timeout bounds --expect/--fail-on; pass one of them, or "
                         "--duration to bound the run")
    checks, ended = None, threading.Event()
    with emu, stop_on_signals(stop, (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)), \
            _rfc2217(args.rfc2217, emu.links) as servers:
        info = emu.info()
        if chosen is not None:
            info.update(workers=1, workers_chosen=chosen)
        if servers is not None:
            info["rfc2217"] = servers.urls
        _emit(info)
        if args.expect or args.fail_on:
            from navtwin.emulator.expect import Checks

            checks = Checks(_ThisRun(info, ended), scenario, args.expect, args.fail_on,
                            args.timeout)
            watcher = threading.Thread(target=lambda: (checks.run(), stop.set()), daemon=True)
            watcher.start()
        summary = emu.run(stop)
        ended.set()
        if checks is not None:
            watcher.join()
    if emu.record_error is not None:  # the run ended there; the recording is closed
        summary["recording_error"] = str(emu.record_error)
    _emit(summary)  # after close: the recording is complete when "done" appears
    if emu.record_error is not None:
        raise UsageError(f"--record {emu.record_error}")
    if checks is not None and checks.failure is not None:
        print(f"navtwin emulate: {checks.failure}", file=sys.stderr, flush=True)
        return EXPECT_FAILED
    return 0


def _worker_count(args, scenario) -> tuple[int, str | None]:
    """--workers as a count, and how auto chose it (None when given)."""
    from navtwin.emulator import workers

    if args.workers != "auto":
        return args.workers, None
    k = workers.auto(scenario, scenario.seed if args.seed is None else args.seed, args.speed)
    return k, f"auto: {len(scenario.fleet)} vehicles at {workers.BUDGET:g} core per worker"


def _run_workers(args, scenario, k: int, chosen: str | None) -> int:
    """The run on *k* worker processes (emulator.workers): one ready and one done line."""
    from navtwin.emulator.pty import LinkDirError
    from navtwin.emulator.runner import RunError
    from navtwin.emulator.workers import Workers

    for given, flag in ((args.record, "--record"), (args.expect or args.fail_on, "--expect/--fail-on")):
        if given:
            raise UsageError(f"{flag} needs the one loop of a single process; pass --workers 1 "
                             f"with it")
    stop = threading.Event()
    try:
        with stop_on_signals(stop, (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)), \
                Workers(scenario, args.seed, k, speed=args.speed, duration_s=args.duration,
                        link_dir=args.link_dir, timing=args.timing, progress=not args.quiet,
                        chosen=chosen) as run, _rfc2217(args.rfc2217, run.links) as servers:
            info = run.info()
            if servers is not None:
                info["rfc2217"] = servers.urls
            _emit(info)
            summary = run.run(stop)
    except (LinkDirError, RunError) as e:
        raise UsageError(flagged(str(e))) from None
    _emit(summary)
    return 0


def _emit(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj, separators=(",", ":")) + "\n")
    sys.stdout.flush()
