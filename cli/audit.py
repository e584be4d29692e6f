"""``navtwin audit``: did the host lose only what the injected faults damaged?"""
from __future__ import annotations

import json
import sys

from .main import UsageError

DESCRIPTION = """\
Compare an emulator recording (navtwin emulate --record, with its fault ledger faults.jsonl)
with a host recording of the same run (navtwin host --record): every frame that reached the
host intact was accepted, every byte the host rejected was touched by an injected fault,
every injection that changed bytes was rejected, and the host's recording holds every read
the host made, in order (its read columns; an older recording without them gets a note).
Bytes the host never read are reported as unseen, by the cause the host saw. Prints a
one-screen report (or --json) and exits 0 when all hold, 1 when one does not."""


def register(sub) -> None:
    p = sub.add_parser("audit", help="check a host recording against the emulator's fault ledger",
                       description=DESCRIPTION)
    p.add_argument("emulator", metavar="EMULATOR_RECORDING")
    p.add_argument("host", metavar="HOST_RECORDING")
    p.add_argument("--json", action="store_true", help="the result as one JSON object")
    p.set_defaults(func=run_audit)


def run_audit(args) -> int:
    from navtwin.lab.audit import AuditError, audit, report
    from navtwin.protocols.recording import RecordingError

    try:
        result = audit(args.emulator, args.host)
    except (AuditError, RecordingError) as e:
        raise UsageError(str(e)) from None
    sys.stdout.write(json.dumps(result) + "\n" if args.json else report(result))
    return 0 if result["ok"] else 1
