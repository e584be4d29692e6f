"""``navtwin pcap``: the arguments of :func:`navtwin.protocols.capture.write_recording`, its
summary line, and the path of the shipped Wireshark dissectors (``--dissectors``)."""
from __future__ import annotations

import os
import sys

from .main import UsageError


def register(sub) -> None:
    p = sub.add_parser(
        "pcap", help="write a recording as a pcapng capture Wireshark decodes",
        description="Write every chunk of a recording's ports as a pcapng capture: one "
        "interface per port (both directions: what the host wrote to the coordinator is "
        "outbound on xbee), one packet per chunk, in time order across the ports, on the "
        "device clock (a host recording has wall times only) or --clock wall; each packet's "
        "comment holds the other clock and the fault-ledger entries that touch its bytes. "
        "navtwin's Lua dissectors decode the SINS frames, nanoLOC reports and XBee API frames: "
        "tshark -X lua_script:$(navtwin pcap --dissectors) -r FILE.pcapng, or copy the file to "
        "~/.local/lib/wireshark/plugins/. Prints one summary line to stderr.")
    p.add_argument("recording", nargs="?", metavar="RECORDING",
                   help="a recording directory (navtwin emulate --record, navtwin host --record)")
    p.add_argument("-o", "--out", metavar="FILE.pcapng",
                   help="the capture to write (- for stdout: navtwin pcap REC -o - | wireshark -k -i -)")
    p.add_argument("--clock", choices=("device", "wall"), default="device",
                   help="the packets' timestamps: device time (default; wall time in a recording "
                   "without it) or wall time (paced runs and host recordings)")
    p.add_argument("--dissectors", action="store_true",
                   help="print the path of navtwin's Wireshark Lua dissectors and exit")
    p.set_defaults(func=run)


def run(args) -> int:
    from navtwin.protocols.capture import (CaptureError, clock_for, dissectors_path,
                                            write_recording)
    from navtwin.protocols.recording import Recording, RecordingError, write_failure

    if args.dissectors:
        if args.recording or args.out:
            raise UsageError("--dissectors prints the Lua file's path; give it alone")
        print(dissectors_path())
        return 0
    if not args.recording or not args.out:
        raise UsageError("give a recording directory and --out FILE.pcapng "
                         "(or --dissectors for the Lua file's path)")
    try:  # bad input is found before the output is touched
        recording = Recording(args.recording)
        clock_for(recording, args.clock)
        recording.faults()
    except (RecordingError, CaptureError) as e:
        raise UsageError(str(e)) from None  # main says a setting's flag
    try:
        out = sys.stdout.buffer if args.out == "-" else open(args.out, "wb")
    except OSError as e:
        raise UsageError(f"--out {write_failure(args.out, e)}") from None
    try:
        try:
            written = write_recording(recording, out, clock=args.clock)
        finally:
            if args.out != "-":
                out.close()
    except (RecordingError, CaptureError, OSError) as e:
        if os.path.isfile(args.out) and not os.path.islink(args.out):
            os.unlink(args.out)  # a capture cut short would look whole to Wireshark
        if isinstance(e, OSError):
            raise UsageError(f"--out {write_failure(args.out, e)}") from None
        raise UsageError(str(e)) from None
    note = " (the recording has no device times)" if written.clock != args.clock else ""
    print(f"navtwin pcap: {args.out}: {written.summary()}{note}", file=sys.stderr)
    return 0
