"""``navtwin host``: the arguments of :class:`navtwin.host.service.Service`; and the options it shares
with ``navtwin replay`` (:mod:`navtwin.cli.replay`): config, filters and the estimate output."""
from __future__ import annotations

import argparse
import sys
import threading

from navtwin.common.limits import MAX_DURATION_S, span
from navtwin.protocols.ports import DEFAULT_BAUD

from .main import BAUD_HELP, UsageError, baud, flag, number, stop_on_signals

STATUS_PERIODS = (0, 3600)
PORT_HELP = ("a device path (/dev/ttyUSB0, an emulator PTY link) or a pyserial URL "
             "(socket://, rfc2217://, spy://)")


def register(sub) -> None:
    p = sub.add_parser("host", help="run the lab computer's fusion service on live serial "
                       "ports", options=_options)
    p.set_defaults(func=run)


def _options(p) -> None:
    from navtwin.host.output import GEODETIC_KEYS, KEYS
    from navtwin.protocols import ports

    p.description = (
        "Read the coordinator (API mode; or the SINS board's direct line) and the "
        "nanoLOC gateway, fuse IMU and ranges, and write one JSON line per estimate: "
        "{" + ",".join(f'"{k}"' for k in KEYS) + "}; with [output] geodetic = true in the "
        "config also " + ", ".join(f'"{k}"' for k in GEODETIC_KEYS) + " (deg, deg, m WGS-84) "
        "after \"y\". A status line goes to stderr every few "
        "seconds; a port that disappears is reopened every 0.5 s while the filters keep their "
        "state (an emulator's link only while that emulator runs). Ports are opened "
        "exclusively (flock, as picocom does). SIGINT or SIGTERM ends the run with a summary "
        "line on stderr (exit 0).")
    # an option per port the host reads (protocols.ports: a package's port gets one too)
    for i, name in enumerate(ports.host_inputs()):
        doc = ports.get(name).doc
        p.add_argument(f"--{name}", metavar="PORT",
                       help=f"{doc}: {PORT_HELP}" if i == 0 else f"{doc} (same forms)")
    p.add_argument("--api1", dest="escaped", action="store_false", default=True,
                   help="the coordinator runs API mode 1 (AP=1); default API mode 2, escaped")
    p.add_argument("--baud", type=baud, default=DEFAULT_BAUD, help=BAUD_HELP)
    common_options(p)
    p.add_argument("--calibration", metavar="NAME|FILE",
                   help="001's range calibration ('navtwin calibrate'): its f and c_i correct "
                        "every range (default: the config's [calibration], if any)")
    p.add_argument("--record", metavar="DIR",
                   help="record every chunk read, with its arrival time, in a new directory, "
                        "not a symbolic link ('navtwin replay DIR' then gives the same output); "
                        "flushed every 0.5 s, so a killed run leaves a replayable recording")
    p.add_argument("--innovations", metavar="FILE",
                   help="also write one JSON line per fusion-track update (t, vehicle, filter, "
                        "kind, dim, nis, accepted) to FILE; the estimates are the same without")
    p.add_argument("--duration", type=number(0, MAX_DURATION_S, above=True), metavar="S",
                   help=f"stop after S seconds of wall time, S {span(0, MAX_DURATION_S, True)} "
                        "(default: run until SIGINT/SIGTERM)")
    p.add_argument("--status-period", type=number(*STATUS_PERIODS, above=True), default=2.0,
                   metavar="S", help="seconds between status lines on stderr, "
                                     f"{span(*STATUS_PERIODS, True)} (default 2)")


def common_options(p, recorded: bool = False) -> None:
    from navtwin.host import config as host_config
    from navtwin.host import tracks

    src = "the recorded run's" if recorded else "the config's"
    p.add_argument("--config", metavar="NAME|FILE",
                   help=f"host config: {', '.join(host_config.shipped())} or a TOML file "
                        f"(default: {'the recorded config' if recorded else host_config.DEFAULT})")
    p.add_argument("--filters", metavar="LIST", type=_filters,
                   help=f"comma list of {','.join(tracks.names())}, or all "
                        f"(default: {src})")
    p.add_argument("--out", default="-", metavar="FILE|-",
                   help="estimate lines (default - = stdout)")


def _filters(text: str) -> tuple[str, ...]:
    from navtwin.common.extras import MissingExtra
    from navtwin.host import config as host_config
    from navtwin.host.config import ConfigError

    try:
        return host_config.parse_filters(text)
    except (ConfigError, MissingExtra) as e:  # a track's extra: its one line
        raise argparse.ArgumentTypeError(str(e).removeprefix("filters: ")) from None


def config_and_filters(args, default_config: bool):
    from navtwin.host import config as host_config
    from navtwin.host.config import ConfigError

    try:
        cfg = host_config.load(args.config) if (args.config or default_config) else None
    except ConfigError as e:
        raise UsageError(str(e)) from None
    return cfg, args.filters


def with_calibration(cfg, spec: str):
    """*cfg* with the calibration file *spec* in place of its own range correction."""
    from navtwin.host import config as host_config
    from navtwin.host.calibration import CalibrationError, load
    from navtwin.host.config import ConfigError

    try:
        return host_config.with_calibration(cfg, load(spec))
    except (CalibrationError, ConfigError) as e:
        raise UsageError(f"--calibration {e}") from None


def open_out(spec: str, option: str = "--out"):
    from navtwin.host.output import open_output

    try:
        return open_output(spec)
    except OSError as e:
        raise UsageError(f"{option} {spec}: {e.strerror}; choose a writable file or -") from None


def close_out(out, option: str = "--out") -> str | None:
    """Close (or flush, for stdout) the estimate output; the failure, if any, as one line."""
    from navtwin.protocols.recording import write_failure

    try:
        out.flush() if out is sys.stdout else out.close()
    except BrokenPipeError:
        raise
    except OSError as e:
        if out is not sys.stdout:
            try:
                out.close()  # what could not be written is lost: close the file all the same
            except OSError:
                pass
        return f"{option} {write_failure(out.name, e)}"
    return None


def run(args) -> int:
    from navtwin.protocols.ports import host_inputs
    from navtwin.host.service import OutputError, Service, StartError

    ports = {p: getattr(args, p) for p in host_inputs() if getattr(args, p, None)}
    if not ports:
        raise UsageError("no input port; give --xbee PORT and/or --sins PORT, and --nanoloc PORT")
    cfg, filters = config_and_filters(args, default_config=True)
    if args.calibration:
        cfg = with_calibration(cfg, args.calibration)
    out = open_out(args.out)
    innovations = None
    stop = threading.Event()
    error = None
    try:
        if args.innovations:
            innovations = open_out(args.innovations, "--innovations")
        service = Service(ports, cfg, filters or cfg.filters, out=out, escaped=args.escaped,
                          baud=args.baud, record=args.record, status=sys.stderr,
                          status_period_s=args.status_period, innovations=innovations)
        with stop_on_signals(stop):
            service.run(stop, duration_s=args.duration)
    except StartError as e:
        raise UsageError(str(e)) from None
    finally:
        # the run's own write error comes first; closing may fail on what was left buffered
        error = close_out(out)
        if innovations is not None:
            error = error or close_out(innovations, "--innovations")
    if service.error is not None:
        where = service.error.setting if isinstance(service.error, OutputError) else "record"
        raise UsageError(f"{flag(where)} {service.error}")
    if error:
        raise UsageError(error)
    return 0
