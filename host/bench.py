"""Measurements of the host on bytes it is given (the lab's benchmarks, :mod:`navtwin.lab.bench`,
give it the emulated lab's).

``bench_latency``: the host service runs in-process on two PTY pairs (coordinator and
gateway); this process writes the chunks to the masters at their arrival times and
measures, for every batch of estimate lines, the time from the write of the chunk holding
the last byte the host had processed to the moment the lines were written (p50/p99/max).
``replay_speeds``: the pipeline over a recording (a host or emulator recording) with each of
several filter sets, their runs interleaved, in multiples of real time = recorded span /
median wall time. ``write_host_recording``: chunks as ``navtwin host
--record`` records them.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navtwin.common.schema import between, key, takes
from navtwin.protocols.ports import DEFAULT_BAUD
from navtwin.protocols.recording import Read, Recording, RecordingWriter

from .config import HostConfig
from .output import percentiles_ms
from .replay import chunks as replay_chunks, replay, settings
from .service import Service, recording_meta


def write_host_recording(directory: str | os.PathLike, config: HostConfig, filters, chunks, *,
                         escaped: bool = True, baud: int = DEFAULT_BAUD) -> Path:
    """A recording as ``navtwin host --record`` makes it, from ``(port, bytes, ns)``."""
    chunks = list(chunks)
    ports = {p: f"synthetic:{p}" for p in dict.fromkeys(c[0] for c in chunks)}
    meta = recording_meta(config, tuple(filters), escaped, ports, baud)
    with RecordingWriter(directory, meta, reads=True) as rec:
        for port, data, t_ns in chunks:
            w = rec.port(port)
            w.write(data, t_wall_ns=t_ns, read=Read(w.offset, 0, 0))  # all read, none contended
    return Path(directory)


# -- measurements ----------------------------------------------------------------------------

class _Discard:
    def write(self, s: str) -> int:
        return len(s)

    def flush(self) -> None:
        pass


def bench_latency(config: HostConfig, filters, chunks, seconds: float) -> dict:
    """Last byte written to the PTY -> estimate lines written, per batch of lines, with the
    ``(port, bytes, arrival ns)`` *chunks* (of *seconds*) written at their arrival times."""
    import tty

    pairs = {}
    for port in ("xbee", "nanoloc"):
        master, slave = os.openpty()
        tty.setraw(slave)
        pairs[port] = (master, slave, os.ttyname(slave))
    writes: dict[str, list[tuple[int, int]]] = {p: [] for p in pairs}  # (cumulative bytes, ns)
    done: list[tuple[str, int, int]] = []
    service = Service({p: v[2] for p, v in pairs.items()}, config, filters, out=_Discard(),
                      on_lines=lambda port, nbytes, ns: done.append((port, nbytes, ns)))
    stop = threading.Event()
    runner = threading.Thread(target=service.run, args=(stop,), daemon=True)
    runner.start()
    service.started.wait(30)
    t0 = time.monotonic_ns()
    total = dict.fromkeys(pairs, 0)
    for port, data, t_ns in chunks:
        delay = (t0 + t_ns - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)
        total[port] += len(data)
        # stamped before the write: the host may read the bytes before os.write returns
        writes[port].append((total[port], time.monotonic_ns()))
        os.write(pairs[port][0], data)
    deadline = time.monotonic() + 10
    while service.bytes != total and time.monotonic() < deadline:
        time.sleep(0.01)
    stop.set()
    runner.join()
    for master, slave, _ in pairs.values():
        os.close(master)
        os.close(slave)
    lat = []
    for port, nbytes, ns in done:
        ends = writes[port]
        # the write that carried the last processed byte
        i = min(np.searchsorted([e for e, _ in ends], nbytes), len(ends) - 1)
        lat.append(ns - ends[i][1])
    return {"benchmark": "latency", "seconds": seconds, "filters": list(filters),
            "batches": len(done), **percentiles_ms(lat),
            "host_side": service.latency.overall()}


def replay_speeds(directory: str | os.PathLike, sets: dict, runs: int = 1) -> dict:
    """Replay speed of the recording in *directory* with each of *sets* (name -> filters,
    None: the recorded run's), the median wall time of *runs* replays each, and the median
    CPU time (a set's cost: what its ratio to another is taken in, a loaded machine's other
    processes left out), the runs interleaved (set a, set b, set a, ...) so that a drift in
    the machine's speed weighs on every set alike; name -> its result."""
    rec = Recording(directory)
    stamps = [t_ns for _, _, t_ns in replay_chunks(rec, settings(rec)["inputs"])]
    recorded_s = (max(stamps) - min(stamps)) / 1e9
    walls: dict[str, list[float]] = {name: [] for name in sets}
    cpus: dict[str, list[float]] = {name: [] for name in sets}
    lines, used = {}, {}
    for _ in range(runs):
        for name, filters in sets.items():
            count = [0]
            t, c = time.perf_counter(), time.process_time()
            pipe = replay(rec, lambda es: count.__setitem__(0, count[0] + len(es)),
                          **({"filters": tuple(filters)} if filters else {}))
            walls[name].append(time.perf_counter() - t)
            cpus[name].append(time.process_time() - c)
            lines[name], used[name] = count[0], list(pipe.filters)
    out = {}
    for name, w in walls.items():
        wall = float(np.median(w))
        out[name] = {"benchmark": "replay", "recording": str(directory),
                     "recorded_s": round(recorded_s, 3), "runs": runs, "wall_s": round(wall, 3),
                     "wall_s_range": [round(min(w), 3), round(max(w), 3)],
                     "cpu_s": round(float(np.median(cpus[name])), 3),
                     "x_real_time": round(recorded_s / wall, 1), "lines": lines[name],
                     "filters": used[name]}
    return out


@dataclass(frozen=True)
class Steps:
    """host-filters' settings."""
    steps: int | None = key(None, "", "steps per timing run; none = 2000 (200 quick)",
                            between(1, 1_000_000))


def benchmarks() -> dict:
    """The host's own benchmarks for ``navtwin bench`` (a set of navtwin.cli.bench.SETS);
    those on the emulated lab's bytes are the lab's (:mod:`navtwin.lab.bench`)."""
    @takes(Steps)
    def host_filters(quick: bool, s: Steps) -> dict:
        """host: microseconds per step of each filter, the strapdown and the estimator"""
        from .bench_filters import measure

        us = measure(s.steps or (200 if quick else 2000))
        return {"benchmark": "host-filters", "us_per_step": {k: round(v, 2) for k, v in us.items()},
                # 100 IMU samples per second of the lab
                "estimator_x_real_time": round(1e6 / (100 * us["estimator/imu"]), 1)}

    return {"host-filters": host_filters}
