"""``navtwin replay``: the host's pipeline over a recording instead of live ports.

A host recording (``navtwin host --record DIR``) holds every chunk the live run processed
with its arrival stamp, and the run's config, filters and API mode in its meta. Feeding the
chunks in stamp order through a :class:`host.pipeline.Pipeline` built from that meta gives
exactly the live run's estimate lines, byte for byte (the pipeline never reads a clock).

An emulator recording (``navtwin emulate --record DIR``) has device times but no arrival
times. Arrival is then synthesised as the time the chunk's last byte leaves the UART,
``t_device_ns + size x 10 / baud`` (8N1), made strictly increasing across ports in the
order ``xbee``, ``sins``, ``nanoloc`` for equal times. Of the two SINS paths the radio
(``xbee``) is used when recorded. That is a deterministic offline run of the host on the
emulated lab; it equals no live run (a live host adds the PTY and scheduling delays).
"""
from __future__ import annotations

import heapq
from typing import Callable, Iterator

from protocols.recording import Recording, RecordingError

from . import config as host_config
from .config import HostConfig
from .pipeline import INPUTS, Pipeline
from .service import HOST_SOURCE


def is_host_recording(rec: Recording) -> bool:
    return rec.meta.get("source") == HOST_SOURCE and "host" in rec.meta


def _host_meta(rec: Recording) -> dict:
    """The recorded run's settings, checked for shape (one-line errors)."""
    h = rec.meta["host"]
    ok = (isinstance(h, dict) and isinstance(h.get("config"), dict)
          and isinstance(h.get("filters"), list) and all(isinstance(f, str) for f in h["filters"])
          and isinstance(h.get("escaped"), bool) and isinstance(h.get("inputs"), list)
          and h["inputs"] and all(p in INPUTS and p in rec.ports for p in h["inputs"]))
    if not ok:
        raise RecordingError(f"{rec.directory / 'recording.json'}: \"host\" is not "
                             f"{{config: object, filters: [names], escaped: bool, inputs: "
                             f"[recorded ports]}}; re-record, or pass --config and --filters")
    return h


def settings(rec: Recording, *, config: HostConfig | None = None,
             filters: tuple[str, ...] | None = None, escaped: bool | None = None) -> dict:
    """Pipeline keyword arguments for *rec*: the live run's, unless overridden."""
    if is_host_recording(rec):
        h = _host_meta(rec)
        cfg = config or host_config.from_dict(h["config"], f"{rec.directory}: recorded config")
        return {"config": cfg, "filters": filters or tuple(h["filters"]),
                "inputs": tuple(h["inputs"]),
                "escaped": h["escaped"] if escaped is None else escaped}
    inputs = [p for p in INPUTS if p in rec.ports]
    if "xbee" in inputs and "sins" in inputs:
        inputs.remove("sins")
    if not inputs:
        raise RecordingError(f"{rec.directory}: none of the ports {', '.join(INPUTS)} is recorded")
    if config is None:
        name = str(rec.meta.get("scenario", ""))
        known = host_config.shipped()
        match = next((n for n in known if name == n or name.startswith(n + "-")), None)
        config = host_config.load(match)
    api = rec.meta.get("ports", {}).get("xbee", {}).get("api_mode", 2)
    return {"config": config, "filters": filters or config.filters, "inputs": tuple(inputs),
            "escaped": (api == 2) if escaped is None else escaped}


def chunks(rec: Recording, inputs: tuple[str, ...]) -> Iterator[tuple[str, bytes, int]]:
    """``(port, bytes, arrival ns)`` in processing order."""
    if is_host_recording(rec):
        for c in rec.merged(list(inputs)):
            yield c.port, c.data, c.t_wall_ns
        return
    bauds = {p: rec.meta.get("ports", {}).get(p, {}).get("baud", 115200) for p in inputs}
    order = {p: i for i, p in enumerate(INPUTS)}

    def arrivals(port: str):
        ns_per_byte = 10 * 1_000_000_000 / bauds[port]
        for c in rec.chunks(port):
            t = c.t_device_ns if c.t_device_ns is not None else c.t_wall_ns
            if t is None:
                raise RecordingError(f"{rec.directory}: port {port!r} chunk at offset {c.offset} "
                                     f"has no time; cannot replay it")
            yield t + round(len(c.data) * ns_per_byte), order[port], c.offset, c.port, c.data

    last = -1
    for t, _, _, port, data in heapq.merge(*(arrivals(p) for p in inputs)):
        last = max(t, last + 1)
        yield port, data, last


def replay(rec: Recording, emit: Callable[[list], None], *,
           progress: Callable[[float], None] | None = None, estimator=None,
           **overrides) -> Pipeline:
    """Run the pipeline over *rec*, calling *emit* with each batch of estimates; returns the
    pipeline (its ``stats()``). *progress* gets the fraction of bytes done, now and then."""
    kw = settings(rec, **overrides)
    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), estimator=estimator, **kw)
    total = sum(rec.sizes[p] for p in pipe.inputs) or 1
    done = 0
    for n, (port, data, t_ns) in enumerate(chunks(rec, pipe.inputs)):
        out = pipe.feed(port, data, t_ns)
        if out:
            emit(out)
        done += len(data)
        if progress is not None and n % 4096 == 0:
            progress(done / total)
    out = pipe.finish()
    if out:
        emit(out)
    return pipe
