"""The ``navtwin`` console script: one parser, subcommands registered by entry points.

Each package registers its subcommands in the ``navtwin.commands`` entry-point group
(``pyproject.toml``), so this dispatcher imports none of them by name: ``protocols`` keeps
importing nothing of navtwin's. A subcommand module provides ``register(subparsers)``,
which adds its parser and sets ``func(args) -> int``.
"""
from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
from contextlib import contextmanager
from importlib.metadata import entry_points

from . import __version__
from common.limits import number_problem, span
from .serial import BAUDS


class UsageError(Exception):
    """A problem with what the user asked for: printed as one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    def error(self, message):  # one line naming the problem and where to look for the fix
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def number(lo: float = -math.inf, hi: float = math.inf, *, integer: bool = False,
           above: bool = False):
    """An argparse ``type``: a finite number (an integer if *integer*) in [lo, hi], or
    (lo, hi] if *above*; anything else is one line naming the value and the range."""
    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            value = text
        problem = number_problem(value, lo, hi, integer=integer, above=above)
        if problem:
            raise argparse.ArgumentTypeError(f"{text}: {problem}")
        return value

    parse.__name__ = "integer" if integer else "number"  # argparse names it in messages
    return parse


#: ``--baud``: any integer rate in BAUDS (pyserial sets non-standard rates too).
baud = number(*BAUDS, integer=True)
BAUD_HELP = f"serial baud rate {span(*BAUDS)} (default 115200)"


def _sigterm_as_interrupt(signum, frame):
    raise KeyboardInterrupt


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="navtwin", description="Firmware-in-the-loop emulator of a SINS/WSN "
                    "positioning lab, and the lab computer's fusion service.")
    parser.add_argument("--version", action="version", version=f"navtwin {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for ep in sorted(entry_points(group="navtwin.commands"), key=lambda e: e.name):
        ep.load()(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    signal.signal(signal.SIGTERM, _sigterm_as_interrupt)
    try:
        return args.func(args) or 0
    except UsageError as e:
        print(f"navtwin {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:  # e.g. piped into head
        sys.stderr.close()
        return 0


# -- navtwin decode ----------------------------------------------------------------------

def register_decode(sub) -> None:
    p = sub.add_parser("decode", help="decode a byte stream into JSON lines",
                       description="Decode SINS frames, XBee API frames, the SINS stream inside "
                       "XBee 0x90 packets, or nanoLOC reports. One JSON object per line per frame "
                       "and per run of consecutive errors of one kind (with its count), then a "
                       "summary with counts by kind.")
    p.add_argument("source", nargs="?", default="-", metavar="SOURCE",
                   help="a file, - for stdin (default), a recording directory, or a serial port "
                        "or pyserial URL (socket://, rfc2217://, spy://, loop://)")
    p.add_argument("--format", required=True, choices=("sins", "nanoloc", "xbee", "xbee-sins"),
                   help="what the bytes are; xbee-sins rebuilds the SINS stream from 0x90 packets")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--escaped", dest="escaped", action="store_true", default=True,
                      help="XBee API mode 2, escaped (default)")
    mode.add_argument("--api1", dest="escaped", action="store_false", help="XBee API mode 1")
    p.add_argument("--baud", type=baud, default=115200, help=BAUD_HELP)
    p.add_argument("--follow", action="store_true",
                   help="keep reading a port or a growing file until interrupted")
    p.add_argument("--port", help="which port of a recording directory (default: by format)")
    p.add_argument("--gyro-range", type=int, choices=(300, 150, 75), default=300,
                   help="ADIS16350 gyro range in deg/s set by SENS/AVG (default 300)")
    p.add_argument("--hex", action="store_true", help="add each frame's bytes")
    p.add_argument("--errors-only", action="store_true", help="print only errors and the summary")
    p.set_defaults(func=run_decode)


@contextmanager
def stop_on_signals(stop: threading.Event, signals=(signal.SIGINT, signal.SIGTERM)):
    """While active, *signals* set *stop*: a long-running command ends at its next check
    (between chunks, never inside one) and still flushes and summarises."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, lambda *_: stop.set()) for s in signals}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def run_decode(args) -> int:
    from .decode import decode
    from .recording import RecordingError

    stop = threading.Event()
    try:
        with stop_on_signals(stop):
            records = decode(args.source, args.format, escaped=args.escaped, with_hex=args.hex,
                             gyro_range=args.gyro_range, baud=args.baud, follow=args.follow,
                             port=args.port, stop=stop)
            for rec in records:
                if args.errors_only and "format" in rec and "error" not in rec:
                    continue
                sys.stdout.write(json.dumps(rec, separators=(",", ":")) + "\n")
                if args.follow:
                    sys.stdout.flush()
    except FileNotFoundError:
        raise UsageError(f"{args.source}: no such file or port; SOURCE is a file, -, a recording "
                         "directory, a serial port or a pyserial URL") from None
    except (IsADirectoryError, PermissionError, RecordingError) as e:
        raise UsageError(str(e)) from None
    except OSError as e:  # serial ports: missing device, wrong URL
        raise UsageError(f"{args.source}: {e}") from None
    return 0
