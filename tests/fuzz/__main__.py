"""``python -m tests.fuzz [TARGET ...] [--runs N]``: fuzz each target with atheris (all of
them, one after another, when none is named), or ``--replay`` their seeds without atheris.

A target's crash (a broken contract) is written to ``--artifacts`` as crash-<sha1>; run
``python -m tests.fuzz TARGET --replay FILE`` to see it again, atheris or not.
"""
from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
import time
from pathlib import Path

from . import TARGETS

#: the longest input libFuzzer makes: many frames; for a reader, room for its parser's limits
#: (an integer of 4300 digits, nesting past the recursion limit)
MAX_LEN = {"recording": 8192, "scenario": 8192, "host_config": 8192}
DEFAULT_MAX_LEN = 4096
STATUS = re.compile(r"^#(\d+)\t", re.M)  # libFuzzer's progress lines: inputs run so far


def fuzz(name: str, runs: int, artifacts: Path, corpus: Path | None, extra: list[str]) -> None:
    """Fuzz one target in this process (atheris exits the process when done)."""
    import atheris

    with atheris.instrument_imports(include=["navtwin", "json", "tomllib"]):
        target = importlib.import_module(f"tests.fuzz.{name}")
    work = corpus or artifacts / f"{name}-corpus"  # kept: the next run starts from it
    work.mkdir(parents=True, exist_ok=True)
    for i, seed in enumerate(target.SEEDS):
        (work / f"seed-{i}").write_bytes(seed)
    artifacts.mkdir(parents=True, exist_ok=True)
    atheris.Setup([sys.argv[0], f"-runs={runs}", f"-max_len={MAX_LEN.get(name, DEFAULT_MAX_LEN)}",
                   f"-artifact_prefix={artifacts}/{name}-", "-timeout=30", "-print_final_stats=1",
                   *extra, str(work)], target.check)
    atheris.Fuzz()


def replay(name: str, files: list[str]) -> int:
    """The target's contract on its seeds, or on *files* (crash inputs); no atheris needed."""
    target = importlib.import_module(f"tests.fuzz.{name}")
    inputs = [Path(f).read_bytes() for f in files] if files else target.SEEDS
    for data in inputs:
        target.check(data)
    return len(inputs)


def fuzz_all(names: list[str], args, libfuzzer: list[str]) -> int:
    """Each target in its own process; a table of runs, wall time and inputs per second."""
    print(f"{'target':12} {'runs':>9} {'wall s':>8} {'exec/s':>8}  result")
    failed = 0
    for name in names:
        cmd = [sys.executable, "-m", "tests.fuzz", name, "--runs", str(args.runs),
               "--artifacts", str(args.artifacts), *libfuzzer]
        t0 = time.monotonic()
        log = args.artifacts / f"{name}.log"
        args.artifacts.mkdir(parents=True, exist_ok=True)
        with open(log, "w") as fh:
            p = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT)
        wall = time.monotonic() - t0
        n = max(map(int, STATUS.findall(log.read_text(errors="replace"))), default=0)
        result = "ok" if p.returncode == 0 else f"CRASH (exit {p.returncode}), see {log}"
        if p.returncode:
            failed += 1
        print(f"{name:12} {n:9d} {wall:8.1f} {n / wall:8.0f}  {result}", flush=True)
    return 1 if failed else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__.split("\n\n")[0])
    ap.add_argument("targets", nargs="*", metavar="TARGET",
                    help=f"one or more of {', '.join(TARGETS)} (default: all)")
    ap.add_argument("--runs", type=int, default=1_000_000, help="inputs per target")
    ap.add_argument("--artifacts", type=Path, default=Path("fuzz-artifacts"),
                    help="where crash inputs and corpora are written (default: %(default)s)")
    ap.add_argument("--corpus", type=Path,
                    help="a single target's corpus (default: ARTIFACTS/TARGET-corpus)")
    ap.add_argument("--replay", nargs="*", metavar="FILE",
                    help="run the contracts on FILEs (default: the seeds), without atheris")
    args, libfuzzer = ap.parse_known_args(argv)  # the rest: libFuzzer flags, e.g. -jobs=2
    names = args.targets or list(TARGETS)
    if unknown := sorted(set(names) - set(TARGETS)):
        ap.error(f"unknown target {unknown[0]!r}; use one of {', '.join(TARGETS)}")
    if args.replay is not None:
        for name in names:
            print(f"{name}: {replay(name, args.replay)} inputs keep the contracts")
        return 0
    if len(names) == 1:
        fuzz(names[0], args.runs, args.artifacts, args.corpus, libfuzzer)
    return fuzz_all(names, args, libfuzzer)


if __name__ == "__main__":
    sys.exit(main())
