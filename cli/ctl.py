"""``navtwin ctl``: break a running lab at the moment you choose (its control socket)."""
from __future__ import annotations

import json
import sys

from navtwin.common.limits import MAX_DURATION_S, VEHICLES
from navtwin.protocols.linkdir import default_link_dir

from .main import UsageError, number

DESCRIPTION = """\
Talk to a running `navtwin emulate` through the control socket in its link directory
(DIR/control, mode 0600). Each command prints the emulator's JSON reply on stdout:

  status                      virtual time, ports (plugged, attached), live faults, tap
                              readers (clients, dropped)
  fault KIND:key=value,...    inject a fault now (e.g. bit_errors:port=xbee,ber=1e-4), for
                              --duration S or until cleared; its id is in the reply
  clear [ID]                  end one live fault, or all
  unplug PORT / replug PORT   pull a port's cable (its link vanishes, clients read a hang-up)
                              and plug it back (a new PTY behind the same link)
  reset board|coordinator     power-cycle the SINS board (its counter starts again) or the
                              coordinator (modem status 0x00, 0x06) now, --duration S off;
                              --vehicle N: car N's board (or its own coordinator)

The fault kinds and their settings are those of a scenario's [[faults]] (docs/scenarios.md);
live faults have no start_s/end_s: they start now. A refusal is one line on stderr, exit 2;
so is "busy", when the lab has all the clients it takes connected: try again."""


def register(sub) -> None:
    p = sub.add_parser("ctl", help="control a running emulator: faults, unplug, status",
                       description=DESCRIPTION, formatter_class=_raw())
    p.add_argument("--link-dir", metavar="DIR", default=None,
                   help=f"the emulator's link directory (default: {default_link_dir()})")
    p.add_argument("--timeout", type=number(0, 600, above=True), default=10.0, metavar="S",
                   help="seconds to wait for the reply (default 10)")
    p.add_argument("op", choices=("status", "fault", "clear", "unplug", "replug", "reset"))
    p.add_argument("arg", nargs="?", help="the fault (KIND:key=value,...), the fault id, the "
                                          "port, or the device (board, coordinator)")
    p.add_argument("--duration", type=number(0, MAX_DURATION_S, above=True), metavar="S",
                   help="with fault: how long it lasts (default: until cleared); with reset: "
                        "how long the device is off (default 0.5)")
    p.add_argument("--vehicle", type=number(*VEHICLES, integer=True), metavar="N",
                   help="with reset: car N's device (default 1); a fault names its car in its "
                        "settings (board_reset:vehicle=2, byte_drop:port=sins2,...)")
    p.set_defaults(func=run_ctl)


def _raw():
    import argparse

    return argparse.RawDescriptionHelpFormatter


def run_ctl(args) -> int:
    from navtwin.emulator.control import Control, ControlError

    op, arg = args.op, args.arg
    needs = {"fault": "the fault as KIND:key=value,...", "unplug": "the port (sins, xbee, "
             "nanoloc)", "replug": "the port (sins, xbee, nanoloc)",
             "reset": "the device (board, coordinator)"}
    if op in needs and arg is None:
        raise UsageError(f"ctl {op} needs {needs[op]}")
    if args.duration is not None and op not in ("fault", "reset"):
        raise UsageError("--duration goes with ctl fault and ctl reset only")
    if args.vehicle is not None and op != "reset":
        raise UsageError("--vehicle goes with ctl reset only; a fault names its car in its settings")
    request: dict = {}
    if op == "fault":
        from navtwin.emulator.scenario import ScenarioError, parse_fault  # only a fault needs it

        try:
            request["fault"] = parse_fault(arg, "ctl fault")
        except ScenarioError as e:
            raise UsageError(str(e)) from None
        if args.duration is not None:
            request["duration_s"] = args.duration
    elif op == "clear" and arg is not None:
        if not (arg.isascii() and arg.isdigit() and len(arg) <= 19):  # an int64, as ids are
            raise UsageError(f"ctl clear {arg[:40]}: a fault id is a number (see ctl status)")
        request["id"] = int(arg)
    elif op in ("unplug", "replug"):
        request["port"] = arg
    elif op == "reset":
        request["device"] = arg
        if args.vehicle is not None:
            request["vehicle"] = args.vehicle
        if args.duration is not None:
            request["duration_s"] = args.duration
    ctl = Control(args.link_dir or default_link_dir(), timeout=args.timeout)
    try:
        reply = ctl.call(op, **request)
    except ControlError as e:  # a refusal, "busy", or no lab to ask
        raise UsageError(str(e)) from None
    sys.stdout.write(json.dumps(reply, separators=(",", ":")) + "\n")
    return 0
