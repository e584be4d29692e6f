"""``navtwin diff``: the arguments of :func:`navtwin.protocols.diff.diff_recordings` (or
:func:`~navtwin.protocols.diff.diff_bytes` with ``--format``), its result as text or JSON,
and ``diff``'s exit status."""
from __future__ import annotations

import json
import sys

from navtwin.protocols.formats import FORMATS

from .main import UsageError, number

EQUAL, DIFFERENT = 0, 1  # bad input is 2, as for every command


def register(sub) -> None:
    p = sub.add_parser(
        "diff", help="compare two recordings (or byte files) frame by frame",
        description="Compare two recording directories port by port, or two byte files of one "
        "wire format (--format), frame by frame: the first divergence (port, byte offset, "
        "device time), each differing frame with the fields that differ (raw, and the change in "
        "engineering units), frames only in A or only in B (frames with a sequence number are "
        "aligned by it), decode errors only on one side, timing differences of matching frames "
        "beyond --time-tolerance (from the recordings' chunk index), and a summary per port. "
        "Exit status, like diff: 0 equal, 1 different, 2 bad input.")
    p.add_argument("a", metavar="A", help="a recording directory, or a byte file with --format")
    p.add_argument("b", metavar="B", help="the recording directory (or byte file) to compare "
                   "with A")
    p.add_argument("--format", choices=FORMATS.names(),
                   help="A and B are byte files of this wire format, not recordings")
    p.add_argument("--api1", action="store_true",
                   help="with --format: the XBee API frames are API mode 1 (default: 2, "
                   "escaped); recordings say their ports' mode themselves")
    p.add_argument("--port", action="append", metavar="PORT",
                   help="compare only this port of the recordings (repeatable; default: all)")
    p.add_argument("--max", type=number(0, integer=True), default=10, metavar="N",
                   help="show the first N entries of each list (changed frames, frames only "
                   "in A or B, errors, timing) and count the rest (default 10)")
    p.add_argument("--time-tolerance", type=number(0), default=0.001, metavar="S",
                   help="report matching frames whose chunk times differ by more than S "
                   "seconds (device time where both have it, else wall time; default 0.001)")
    p.add_argument("--gyro-range", type=int, choices=(300, 150, 75), default=300,
                   help="ADIS16350 gyro range in deg/s for the SINS words' units (default 300); "
                        "type 01 frames only: a wide sample frame's 32-bit words need none")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=run)


def _read(path: str) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file; with --format, A and B are byte files") \
            from None
    except IsADirectoryError:
        raise UsageError(f"{path}: a directory; drop --format to compare recordings") from None
    except OSError as e:
        raise UsageError(f"{path}: {e.strerror}") from None


def run(args) -> int:
    from navtwin.protocols.diff import DiffError, diff_bytes, diff_recordings
    from navtwin.protocols.recording import RecordingError

    if args.format:
        if args.port:
            raise UsageError("--port names a recording's port; with --format A and B are "
                             "byte files")
        result = diff_bytes(_read(args.a), _read(args.b), args.format, escaped=not args.api1,
                            gyro_range=args.gyro_range, max_shown=args.max,
                            names=(args.a, args.b))
    else:
        if args.api1:
            raise UsageError("--api1 goes with --format; a recording says its ports' API mode")
        try:
            result = diff_recordings(args.a, args.b, ports=args.port,
                                     time_tolerance_s=args.time_tolerance,
                                     gyro_range=args.gyro_range, max_shown=args.max)
        except (RecordingError, DiffError) as e:
            raise UsageError(f"{e} (byte files: give --format)"
                             if isinstance(e, RecordingError) else str(e)) from None
    if args.json:
        sys.stdout.write(json.dumps(result.to_json(), separators=(",", ":")) + "\n")
    else:
        sys.stdout.write(result.text())
    return EQUAL if result.equal else DIFFERENT
