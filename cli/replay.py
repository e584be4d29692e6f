"""``navtwin replay``: the arguments of :func:`navtwin.host.replay.replay`, its estimate lines, and
its progress and summary lines on stderr."""
from __future__ import annotations

import sys
import time

from .host import close_out, common_options, config_and_filters, open_out
from .main import UsageError, number


def register(sub) -> None:
    r = sub.add_parser(
        "replay", help="run the host's pipeline over a recording", options=_options,
        description="Feed a recording through the host's pipeline and write the estimate lines. "
        "A recording made by 'navtwin host --record' gives exactly the live run's lines (its "
        "config, filters and API mode are in the recording; --config and --filters override "
        "them). An emulator recording "
        "('navtwin emulate --record') is run with arrival = the time each chunk's last byte "
        "leaves the UART: a deterministic offline run, not equal to any live run. The lines "
        "are navtwin host's; with [output] geodetic = true in the config they also give lat, "
        "lon (deg) and h (m, WGS-84). Several recordings (DIR DIR ...) are replayed each into "
        "OUT/<its directory name>.jsonl (--out-dir OUT), --jobs N at a time in worker processes, "
        "with one summary line each on stderr.")
    r.set_defaults(func=run)


def _options(r) -> None:
    r.add_argument("directories", nargs="+", metavar="DIR", help="the recording directory (or several)")
    r.add_argument("--out-dir", metavar="OUT",
                   help="with several recordings: write each one's lines to OUT/<its directory "
                        "name>.jsonl (created)")
    r.add_argument("--jobs", type=number(1, 256, integer=True), default=1, metavar="N",
                   help="with several recordings: replay N at a time, each in a worker process "
                        "(default 1)")
    r.add_argument("--salvage", action="store_true",
                   help="replay the intact prefix of a recording that is marked complete but "
                        "whose tail is damaged (an incomplete one, from a killed run, always "
                        "replays its intact prefix)")
    common_options(r, recorded=True)
    r.add_argument("--api1", dest="escaped", action="store_const", const=False, default=None,
                   help="the coordinator in an emulator recording ran API mode 1 "
                        "(default: as its meta says, else 2)")


def run(args) -> int:
    if len(args.directories) > 1 or args.out_dir is not None:
        return run_many(args)
    if args.jobs > 1:
        raise UsageError("--jobs replays several recordings at once; give several DIRs and --out-dir")
    args.directory = args.directories[0]
    from navtwin.host.config import ConfigError
    from navtwin.host.output import estimate_line, info_line
    from navtwin.host.replay import replay, settings
    from navtwin.protocols.recording import Recording, RecordingError, write_failure

    cfg, filters = config_and_filters(args, default_config=False)
    try:
        rec = Recording(args.directory, salvage=args.salvage)
        # before --out opens; the config's [output] says what a line gives
        frame = settings(rec, config=cfg, filters=filters, escaped=args.escaped)["config"].output_frame
    except (RecordingError, ConfigError) as e:
        raise UsageError(str(e)) from None
    if (note := rec.skipped_line()) is not None:
        print(f"navtwin replay: {note}", file=sys.stderr)
    out = open_out(args.out)
    t0 = time.monotonic()
    shown = [t0]

    def emit(estimates: list) -> None:
        out.write("".join(estimate_line(e, frame) for e in estimates))

    def progress(fraction: float) -> None:
        now = time.monotonic()
        if now - shown[0] >= 2.0:
            shown[0] = now
            sys.stderr.write(info_line("progress", {"done": round(fraction, 3),
                                                    "elapsed_s": round(now - t0, 1)}))

    error = None
    try:
        pipe = replay(rec, emit, progress=progress, config=cfg, filters=filters,
                      escaped=args.escaped)
    except BrokenPipeError:
        raise
    except OSError as e:  # the data files are read through RecordingError: this is --out
        error = f"--out {write_failure(args.out, e)}"
    except (RecordingError, ConfigError) as e:
        error = str(e)
    finally:
        error = error or close_out(out)
    if error:
        raise UsageError(error)
    sys.stderr.write(info_line("summary", {"recording": str(rec.directory),
                                           "complete": rec.complete,
                                           **({"skipped": rec.skipped} if rec.skipped else {}),
                                           "elapsed_s": round(time.monotonic() - t0, 3),
                                           **pipe.stats()}))
    return 0


def run_many(args) -> int:
    """Several recordings, each into its own file (host.replays)."""
    from navtwin.host.config import ConfigError
    from navtwin.host.output import info_line
    from navtwin.host.replays import ReplaysError, replay_all

    if args.out_dir is None:
        raise UsageError("several recordings need --out-dir OUT: each one's lines go to "
                         "OUT/<its directory name>.jsonl")
    if args.out != "-":
        raise UsageError("--out names one recording's file; with --out-dir each recording has "
                         "its own, so leave --out out")
    t0 = time.monotonic()
    try:
        for summary in replay_all(args.directories, args.out_dir, args.jobs, config=args.config,
                                  filters=args.filters, escaped=args.escaped, salvage=args.salvage):
            sys.stderr.write(info_line("summary", summary))
    except (ReplaysError, ConfigError) as e:
        raise UsageError(str(e)) from None
    except OSError as e:
        raise UsageError(f"--out-dir {args.out_dir}: {e.strerror}; choose a writable directory") from None
    sys.stderr.write(info_line("replays", {"recordings": len(args.directories), "jobs": args.jobs,
                                           "elapsed_s": round(time.monotonic() - t0, 3)}))
    return 0
