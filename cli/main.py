"""The ``navtwin`` console script: one parser, subcommands found in a registry.

The subcommands are :data:`COMMANDS`: navtwin's own, declared below by ``"module:register"``,
then those of installed packages, from the ``navtwin.commands`` entry-point group, so a user's
package can add one. A subcommand module provides ``register(subparsers)``, which adds its parser and sets
``func(args) -> int``; it reports bad input by raising :class:`UsageError`. A command that needs
an extra (``pyproject.toml``'s optional dependencies) sets ``extra`` too: a module of it that is
not installed is then one line naming the extra (:func:`missing_extra`), exit status 2. Every
command registers every time, so register() imports nothing heavy: ``func`` imports the library
it runs, and options whose help needs a library are added by ``options`` (:class:`Parser`).
"""
from __future__ import annotations

import argparse
import math
import re
import signal
import sys
import threading
from contextlib import contextmanager

from navtwin.common.extras import MissingExtra, install_line
from navtwin.common.limits import span
from navtwin.common.signals import stopper
from navtwin.protocols.plugins import Registry
from navtwin.protocols import __version__
from navtwin.protocols.ports import DEFAULT_BAUD
from navtwin.protocols.serial import BAUDS


class UsageError(Exception):
    """A problem with what the user asked for: printed as one line, exit status 2."""


def flag(setting: str) -> str:
    """The command-line option of library setting *setting*: ``link_dir`` -> ``--link-dir``."""
    return "--" + setting.replace("_", "-")


#: A library error about one setting starts with its name: ``speed: 'x' is not ...``.
_SETTING = re.compile(r"([a-z][a-z0-9_]*): ")


def flagged(message: str) -> str:
    """*message* as the command line says it: a library error that starts with a setting's name
    (``record: /x: not empty``) starts with its option instead (``--record /x: not empty``)."""
    m = _SETTING.match(message)
    return f"{flag(m[1])} {message[m.end():]}" if m else message


class Parser(argparse.ArgumentParser):
    """*options* (a subcommand's ``add_parser(..., options=fn)``): fn(parser) adds the options
    whose help needs a library module, when this parser is first used: ``navtwin --version``
    and every other subcommand do not import it (docs/performance.md). *options_for*:
    fn(parser, args) adds the options that depend on the arguments given, before they are
    parsed (``navtwin bench NAME``'s settings, ``--help`` included), those it has not yet."""

    def __init__(self, *args, options=None, options_for=None, **kwargs):
        super().__init__(*args, **kwargs)
        self._options = options
        self._options_for = options_for

    def _add_options(self) -> None:
        if self._options is not None:
            add, self._options = self._options, None
            add(self)

    def parse_known_args(self, args=None, namespace=None):
        self._add_options()
        if self._options_for is not None:  # each parse: a parser may parse several lines
            args = list(sys.argv[1:] if args is None else args)
            self._options_for(self, args)
        return super().parse_known_args(args, namespace)

    def format_usage(self):
        self._add_options()
        return super().format_usage()

    def format_help(self):
        self._add_options()
        return super().format_help()

    def error(self, message):  # one line naming the problem and where to look for the fix
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def number(lo: float = -math.inf, hi: float = math.inf, *, integer: bool = False,
           above: bool = False):
    """An argparse ``type``: a finite number (an integer if *integer*) in [lo, hi], or
    (lo, hi] if *above*; anything else is one line naming the value and the range."""
    within = span(lo, hi, above)

    def parse(text: str):
        from navtwin.common.schema import Check, Invalid, value  # when a number is parsed

        check = Check(lambda v: (lo < v if above else lo <= v) and v <= hi, f"must be {within}",
                      f"use a value {within}")
        try:
            raw = int(text) if integer else float(text)
        except ValueError:
            raw = text  # the schema names what it should be
        try:
            return value(raw, int if integer else float, text, check)
        except Invalid as e:
            raise argparse.ArgumentTypeError(f"{text}: {e.problem}") from None

    parse.__name__ = "integer" if integer else "number"  # argparse names it in messages
    return parse


#: ``--baud``: any integer rate in BAUDS (pyserial sets non-standard rates too).
baud = number(*BAUDS, integer=True)
BAUD_HELP = f"serial baud rate {span(*BAUDS)} (default {DEFAULT_BAUD})"


@contextmanager
def stop_on_signals(stop: threading.Event, signals=(signal.SIGINT, signal.SIGTERM)):
    """While active, *signals* set *stop*: a long-running command ends at its next check
    (between chunks, never inside one) and still flushes and summarises."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = stopper(stop)
    old = {s: signal.signal(s, handler) for s in signals}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _sigterm_as_interrupt(signum, frame):
    raise KeyboardInterrupt


def missing_extra(e: ModuleNotFoundError, extra: str | None) -> str | None:
    """The line for *e*, a module that is not installed, when the command's *extra* installs
    it, or the line of a :class:`MissingExtra` (a library module that names its extra, in any
    command); None for one of navtwin's own modules or a command without an extra (a broken
    install, whose traceback is the report)."""
    if isinstance(e, MissingExtra):  # a library module named its extra itself
        return str(e)
    name = (e.name or "").partition(".")[0]
    if not extra or not name or name == "navtwin":
        return None
    return install_line(name, extra)


#: The subcommands: name -> register(subparsers), which may add more than one ('navtwin --help'
#: lists them in this order, then those of entry points by name).
COMMANDS = Registry("navtwin.commands", "command", {
    name: f"navtwin.cli.{module}:register" for name, module in (
        ("audit", "audit"), ("bench", "bench"), ("calibrate", "calibrate"), ("ctl", "ctl"),
        ("decode", "decode"), ("demo", "demo"), ("diff", "diff"), ("emulate", "emulate"),
        ("extcap", "extcap"), ("host", "host"), ("host-replay", "replay"), ("lab", "lab"),
        ("pcap", "pcap"), ("report", "report"), ("sweep", "sweep"))})


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="navtwin", description="Firmware-in-the-loop emulator of a SINS/WSN "
                    "positioning lab, and the lab computer's fusion service.")
    parser.add_argument("--version", action="version", version=f"navtwin {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for _, register in COMMANDS.items():
        register(sub)
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
        print(f"navtwin {args.command}: error: {flagged(str(e))}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as e:
        if (line := missing_extra(e, getattr(args, "extra", None))) is None:
            raise
        print(f"navtwin {args.command}: error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:  # e.g. piped into head
        sys.stderr.close()
        return 0
