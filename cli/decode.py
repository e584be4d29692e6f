"""``navtwin decode``: the arguments of :func:`navtwin.protocols.decode.decode`, and its records as
JSON lines."""
from __future__ import annotations

import json
import sys
import threading

from navtwin.protocols.formats import FORMATS
from navtwin.protocols.ports import DEFAULT_BAUD

from .main import BAUD_HELP, UsageError, baud, stop_on_signals


def register(sub) -> None:
    p = sub.add_parser("decode", help="decode a byte stream into JSON lines",
                       description="Decode SINS frames, XBee API frames, the SINS stream inside "
                       "XBee 0x90 packets, or nanoLOC reports. One JSON object per line per frame "
                       "and per run of consecutive errors of one kind (with its count), then a "
                       "summary with counts by kind.")
    p.add_argument("source", nargs="?", default="-", metavar="SOURCE",
                   help="a file, - for stdin (default), a recording directory, or a serial port "
                        "or pyserial URL (socket://, rfc2217://, spy://, loop://)")
    p.add_argument("--format", required=True, choices=FORMATS.names(),
                   help="what the bytes are; xbee-sins rebuilds the SINS stream from 0x90 packets")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--escaped", dest="escaped", action="store_true", default=True,
                      help="XBee API mode 2, escaped (default)")
    mode.add_argument("--api1", dest="escaped", action="store_false", help="XBee API mode 1")
    p.add_argument("--baud", type=baud, default=DEFAULT_BAUD, help=BAUD_HELP)
    p.add_argument("--follow", action="store_true",
                   help="keep reading a port or a growing file until interrupted")
    p.add_argument("--port", help="which port of a recording directory (default: by format)")
    p.add_argument("--gyro-range", type=int, choices=(300, 150, 75), default=300,
                   help="ADIS16350 gyro range in deg/s set by SENS/AVG (default 300); "
                        "type 01 frames only: a wide sample frame's 32-bit words need none")
    p.add_argument("--hex", action="store_true", help="add each frame's bytes")
    p.add_argument("--errors-only", action="store_true", help="print only errors and the summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from navtwin.protocols.decode import decode, printed
    from navtwin.protocols.recording import RecordingError

    stop = threading.Event()
    try:
        with stop_on_signals(stop):
            records = decode(args.source, args.format, escaped=args.escaped, with_hex=args.hex,
                             gyro_range=args.gyro_range, baud=args.baud, follow=args.follow,
                             port=args.port, stop=stop)
            for rec in records:
                if args.errors_only and "format" in rec and "error" not in rec:
                    continue
                sys.stdout.write(json.dumps(printed(rec, args.gyro_range),
                                            separators=(",", ":")) + "\n")
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
