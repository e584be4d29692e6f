"""The reference estimates: what ``navtwin replay`` of an emulator recording gives, for each
shipped scenario and three seeds, kept in fixtures/reference/estimates.npz.

Restructuring must not change them (tests/test_reference.py). Where an output changes on
purpose, regenerate the file in the same commit and say why in its message::

    .venv/bin/python -m tests.reference

The numbers are compared to 1e-9 (relative), not as bytes: another CPU's BLAS kernels may
round the filters' matrix products differently in the last bit.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

SCENARIOS = ("office", "corridor", "corridor-outage")
SEEDS = (1, 2, 3)
FIELDS = ("t", "x", "y", "vx", "vy", "yaw")
PATH = Path(__file__).resolve().parent.parent / "fixtures" / "reference" / "estimates.npz"


def estimate_lines(scenario: str, seed: int) -> list[str]:
    """``navtwin emulate --speed max --record DIR`` then ``navtwin replay DIR``, in process."""
    from navtwin.emulator.runner import Emulation
    from navtwin.emulator.scenario import load_scenario
    from navtwin.host.output import estimate_line
    from navtwin.host.replay import replay
    from navtwin.protocols.recording import Recording

    with tempfile.TemporaryDirectory(prefix="navtwin-ref-") as tmp:
        rec = Path(tmp) / "rec"
        with Emulation(load_scenario(scenario), seed, speed=None, ports=False, record=rec) as emu:
            emu.run()
        lines: list[str] = []
        replay(Recording(rec), lambda es: lines.extend(map(estimate_line, es)))
    return lines


def arrays(lines: list[str]) -> dict[str, np.ndarray]:
    """Per filter: its estimates' fields (yaw NaN where null), variances and flags."""
    by: dict[str, list[dict]] = {}
    for line in lines:
        e = json.loads(line)
        by.setdefault(e["filter"], []).append(e)
    out = {}
    for name, es in by.items():
        out[f"{name}.fields"] = np.array([[np.nan if e[k] is None else e[k] for k in FIELDS]
                                          for e in es], dtype=float)
        # the variances only: the whole 4x4 would treble the file for little more evidence
        out[f"{name}.var"] = np.array([e["cov"][::5] for e in es], dtype=float)
        out[f"{name}.extrapolated"] = np.array([e["extrapolated"] for e in es], dtype=bool)
    return out


def compute() -> dict[str, np.ndarray]:
    return {f"{s}/{seed}/{k}": v for s in SCENARIOS for seed in SEEDS
            for k, v in arrays(estimate_lines(s, seed)).items()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.reference", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.parse_args(argv)
    PATH.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(PATH, **compute())
    print(f"wrote {PATH} ({PATH.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
