"""The reference estimates: what ``navtwin replay`` of an emulator recording gives, for each
shipped scenario and three seeds, kept as digests in fixtures/reference/estimates.json.

Restructuring must not change them (tests/test_reference.py). Where an output changes on
purpose, regenerate the file in the same commit and say why in its message::

    .venv/bin/python -m tests.reference --write
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

SCENARIOS = ("office", "corridor", "corridor-outage")
SEEDS = (1, 2, 3)
PATH = Path(__file__).resolve().parent.parent / "fixtures" / "reference" / "estimates.json"


def estimate_lines(scenario: str, seed: int) -> list[str]:
    """``navtwin emulate --speed max --record DIR`` then ``navtwin replay DIR``, in process."""
    from emulator.runner import Emulation
    from emulator.scenario import load_scenario
    from host.output import estimate_line
    from host.replay import replay
    from protocols.recording import Recording

    with tempfile.TemporaryDirectory(prefix="navtwin-ref-") as tmp:
        rec = Path(tmp) / "rec"
        with Emulation(load_scenario(scenario), seed, speed=None, ports=False, record=rec) as emu:
            emu.run()
        lines: list[str] = []
        replay(Recording(rec), lambda es: lines.extend(map(estimate_line, es)))
    return lines


def digest(lines: list[str]) -> dict:
    """Line count and SHA-256 of all lines, and of each filter's lines (to say which moved)."""
    by_filter: dict[str, list[str]] = defaultdict(list)
    for line in lines:
        by_filter[json.loads(line)["filter"]].append(line)

    def sha(ls):
        return hashlib.sha256("".join(ls).encode()).hexdigest()

    return {"lines": len(lines), "sha256": sha(lines),
            "filters": {f: {"lines": len(ls), "sha256": sha(ls)} for f, ls in sorted(by_filter.items())}}


def compute() -> dict:
    return {s: {str(seed): digest(estimate_lines(s, seed)) for seed in SEEDS} for s in SCENARIOS}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.reference", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--write", action="store_true", help=f"write {PATH} (default: print)")
    args = p.parse_args(argv)
    text = json.dumps(compute(), indent=1, sort_keys=True) + "\n"
    if args.write:
        PATH.write_text(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
