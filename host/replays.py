"""Several recordings replayed at once (``navtwin replay DIR DIR ... --jobs N --out-dir OUT``).

Each recording is replayed as :func:`navtwin.host.replay.replay` replays one, into its own
estimate file ``OUT/<recording's directory name>.jsonl``, the lines ``navtwin replay DIR
--out FILE`` writes; with ``jobs`` > 1 the recordings are spread over that many worker
processes (a recording is one task: its lines do not depend on which worker ran it or in
what order). Every recording and the config are checked before any work starts, so a bad
one is one line and nothing is written. A worker gets only the paths and settings and sends
back its recording's summary (plain data).
"""
from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from navtwin.protocols.recording import Recording, RecordingError

from . import config as host_config
from .output import estimate_line
from .replay import replay, settings


class ReplaysError(ValueError):
    """Recordings that cannot be replayed as asked: one line naming the fix."""


def plan(directories: list[str], out_dir: str | os.PathLike) -> list[tuple[str, str]]:
    """(recording, estimate file) of each recording; ReplaysError if two would share a file."""
    out = Path(out_dir)
    files: dict[str, str] = {}
    for d in directories:
        name = Path(d).resolve().name
        if name in files:
            raise ReplaysError(f"{d} and {files[name]} would both write {out / name}.jsonl; give "
                               "recordings whose directories are named apart")
        files[name] = d
    return [(d, str(out / f"{Path(d).resolve().name}.jsonl")) for d in directories]


def check(directories: list[str], config: str | None, filters, escaped, salvage: bool) -> None:
    """Each recording opens and has what its replay needs (RecordingError, ConfigError)."""
    cfg = host_config.load(config) if config else None
    for d in directories:
        settings(Recording(d, salvage=salvage), config=cfg, filters=filters, escaped=escaped)


def replay_to(directory: str, out_path: str, config: str | None = None, filters=None,
              escaped: bool | None = None, salvage: bool = False) -> dict:
    """Replay *directory* into the estimate file *out_path*; its summary (the CLI's summary
    line's body, with the CPU time it took)."""
    cpu = time.process_time()
    rec = Recording(directory, salvage=salvage)
    cfg = host_config.load(config) if config else None
    frame = settings(rec, config=cfg, filters=filters, escaped=escaped)["config"].output_frame
    with open(out_path, "w", encoding="utf-8") as out:
        pipe = replay(rec, lambda es: out.write("".join(estimate_line(e, frame) for e in es)),
                      config=cfg, filters=filters, escaped=escaped)
    return {"recording": str(rec.directory), "out": out_path, "complete": rec.complete,
            **({"skipped": rec.skipped} if rec.skipped else {}),
            "cpu_s": round(time.process_time() - cpu, 3), **pipe.stats()}


def replay_all(directories: list[str], out_dir: str | os.PathLike, jobs: int = 1, *,
               config: str | None = None, filters=None, escaped: bool | None = None,
               salvage: bool = False) -> Iterator[dict]:
    """Each recording's summary, in the order given, as its replay ends (module doc)."""
    work = plan(directories, out_dir)
    try:
        check(directories, config, filters, escaped, salvage)
    except RecordingError as e:
        raise ReplaysError(str(e)) from None
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    args = [(d, out, config, filters, escaped, salvage) for d, out in work]
    if jobs <= 1 or len(work) == 1:
        yield from (replay_to(*a) for a in args)
        return
    # fork: a worker starts from this process's imports instead of importing them again
    with ProcessPoolExecutor(min(jobs, len(work)), mp_context=multiprocessing.get_context("fork")) as pool:
        yield from pool.map(replay_to, *zip(*args))
