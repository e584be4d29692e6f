"""Benchmarks of the host, and the synthetic lab they run on.

    python -m cli.host_bench latency [--seconds 20] [--filters all]
    python -m cli.host_bench replay [DIR] [--seconds 60] [--filters all]

``latency``: the host service runs in-process on two PTY pairs (coordinator and gateway);
this process writes the synthetic lab's chunks to the masters at their arrival times and
measures, for every batch of estimate lines, the time from the write of the chunk holding
the last byte the host had processed to the moment the lines were written (p50/p99/max).
``replay``: the pipeline over a recording (DIR: a host or emulator recording, e.g. from
``navtwin emulate --scenario office --speed max --record DIR``; default: a synthetic
host recording of --seconds), in multiples of real time = recorded span / wall time.

The synthetic lab (:func:`synthetic_chunks`) is the host's view of a vehicle standing at
the config's start: level SINS samples (local gravity on z, seeded noise of about one LSB)
from a board whose crystal runs ``drift_ppm`` fast, each sent in its own 0x90 packet, and
four-timestamp exchanges with the anchors in turn every 25 ms, every 50th a timeout. The
sample counter and the anchors' ``t_us`` start just before their wraps. Noise comes from a
seeded generator per stream (named spawn keys).
"""
from __future__ import annotations

import math
import os
import tempfile
import threading
import time
import zlib
from pathlib import Path

import numpy as np

from protocols import adis16350, nanoloc, sins, xbee
from protocols.recording import Recording, RecordingWriter

from . import config as host_config
from .config import HostConfig
from .replay import chunks as replay_chunks, replay, settings
from .service import Service, recording_meta

ROUTER64 = 0x0013A20040A1B2D4
ROUTER16 = 0x4F2A
BAUD = 115200
EXCHANGE_S = 0.025
REPLY_PS = 100_000_000  # 100 us processing time at each end of an exchange
SINS_UART_S = sins.FRAME_SIZE * 10 / BAUD


def _rng(seed: int, name: str) -> np.random.Generator:
    key = (zlib.crc32(name.encode()),)  # a fixed, named stream per consumer
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def _wire_s(n: int) -> float:
    return n * 10 / BAUD


def synthetic_chunks(config: HostConfig, seconds: float, *, seed: int = 0, escaped: bool = True,
                     via: str = "xbee", drift_ppm: float = 30.0, start_s: float = 0.05,
                     seq0: int = 65_000, t_us0: int = (1 << 32) - 2_000_000):
    """``(port, bytes, arrival ns)`` of a standing vehicle, in arrival order, stamps unique.
    The devices power up at host time *start_s* with counters *seq0* and *t_us0*."""
    imu_rng, radio_rng, range_rng = _rng(seed, "imu"), _rng(seed, "radio"), _rng(seed, "ranges")
    g_counts = config.gravity / adis16350.STANDARD_GRAVITY
    events = []
    n = int(seconds / sins.PERIOD_S)
    noise = imu_rng.normal(0.0, 1.0, (n, 6))
    glsb, alsb = adis16350.GYRO_LSB_DPS[config.gyro_range_dps], adis16350.ACCEL_LSB_G
    for k in range(n):
        sent = start_s + k * sins.PERIOD_S * (1 + drift_ppm * 1e-6)
        words = adis16350.sample_to_words(gyro_dps=tuple(noise[k, :3] * glsb),
                                          accel_g=(noise[k, 3] * alsb, noise[k, 4] * alsb,
                                                   g_counts + noise[k, 5] * alsb),
                                          gyro_range=config.gyro_range_dps)
        frame = sins.build_sample(seq0 + k, words)
        arrive = sent + SINS_UART_S
        if via == "xbee":
            frame = xbee.build(xbee.FrameType.RECEIVE_PACKET, escaped, src64=ROUTER64,
                               src16=ROUTER16, options=0x01, data=frame)
            arrive += 0.003 + radio_rng.exponential(0.001) + _wire_s(len(frame))
        events.append((arrive, via, frame))
    x0, y0 = config.start
    ids = sorted(config.anchors)
    for i in range(int(seconds / EXCHANGE_S)):
        t = start_s + i * EXCHANGE_S
        aid = ids[i % len(ids)]
        ax, ay, az = config.anchors[aid]
        d = math.dist((x0, y0, config.tag_height), (ax, ay, az)) + range_rng.normal(0.0, 0.05)
        if i % 50 == 49:
            status, tau = nanoloc.STATUS_TIMEOUT, (0, 0, 0, 0)
        else:
            tof_ps = round(d / nanoloc.SPEED_OF_LIGHT * 1e12)
            status, tau = nanoloc.STATUS_COMPLETE, (2 * tof_ps + REPLY_PS, REPLY_PS,
                                                    2 * tof_ps + REPLY_PS, REPLY_PS)
        report = nanoloc.build_report(seq=i, t_us=t_us0 + round((t - start_s) * 1e6), anchor=aid,
                                      tag=0x10, status=status, rssi=-60, tau=tau)
        events.append((t + 0.0005 + _wire_s(len(report)), "nanoloc", report))
    last = -1
    for arrive, port, data in sorted(events, key=lambda e: e[0]):
        last = max(round(arrive * 1e9), last + 1)
        yield port, data, last


def write_host_recording(directory: str | os.PathLike, config: HostConfig, filters, chunks, *,
                         escaped: bool = True) -> Path:
    """A recording as ``navtwin host --record`` makes it, from ``(port, bytes, ns)``."""
    chunks = list(chunks)
    ports = {p: f"synthetic:{p}" for p in dict.fromkeys(c[0] for c in chunks)}
    meta = recording_meta(config, tuple(filters), escaped, ports, BAUD)
    with RecordingWriter(directory, meta) as rec:
        for port, data, t_ns in chunks:
            rec.port(port).write(data, t_wall_ns=t_ns)
    return Path(directory)


# -- benchmarks ---------------------------------------------------------------------------

def _percentiles(ns: list[int]) -> dict:
    ms = np.asarray(ns, float) / 1e6
    if not ms.size:
        return {"n": 0}
    p50, p99 = np.percentile(ms, [50, 99])
    return {"n": int(ms.size), "p50_ms": round(float(p50), 3), "p99_ms": round(float(p99), 3),
            "max_ms": round(float(ms.max()), 3)}


class _Discard:
    def write(self, s: str) -> int:
        return len(s)

    def flush(self) -> None:
        pass


def bench_latency(config: HostConfig, filters, seconds: float, seed: int = 0) -> dict:
    """Last byte written to the PTY -> estimate lines written, per batch of lines."""
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
    chunks = list(synthetic_chunks(config, seconds, seed=seed))
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
            "batches": len(done), **_percentiles(lat),
            "host_side": service.latency.overall()}


def bench_replay(config: HostConfig, filters, seconds: float, directory: str | None = None) -> dict:
    """Replay speed in multiples of real time."""
    with tempfile.TemporaryDirectory() as tmp:
        if directory is None:
            directory = write_host_recording(Path(tmp) / "rec", config, filters,
                                             synthetic_chunks(config, seconds))
        rec = Recording(directory)
        lines = [0]
        stamps = [t_ns for _, _, t_ns in replay_chunks(rec, settings(rec)["inputs"])]
        t = time.perf_counter()
        overrides = {"filters": tuple(filters)} if filters else {}
        pipe = replay(rec, lambda es: lines.__setitem__(0, lines[0] + len(es)), **overrides)
        wall = time.perf_counter() - t
    recorded_s = (max(stamps) - min(stamps)) / 1e9
    return {"benchmark": "replay", "recording": str(directory), "recorded_s": round(recorded_s, 3),
            "wall_s": round(wall, 3), "x_real_time": round(recorded_s / wall, 1),
            "lines": lines[0], "filters": list(pipe.filters)}


def benchmarks() -> dict:
    """The host's benchmarks for ``navtwin bench`` (entry point group navtwin.benchmarks)."""
    def host_latency(quick: bool = False) -> dict:
        """host: last byte on the PTY -> estimate line, all filters (goal p99 <= 2 ms)"""
        return bench_latency(host_config.load(), host_config.FILTER_NAMES, 5.0 if quick else 20.0)

    def host_replay(quick: bool = False) -> dict:
        """host: replay speed of a synthetic office recording, all filters (goal >= 100x)"""
        return bench_replay(host_config.load(), host_config.FILTER_NAMES, 10.0 if quick else 60.0)

    return {"host-latency": host_latency, "host-replay": host_replay}
