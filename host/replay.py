"""``navtwin replay``: the host's pipeline over a recording instead of live ports.

A host recording (``navtwin host --record DIR``) holds every chunk the live run processed
with its arrival stamp, and the run's config, filters and API mode in its meta. Feeding the
chunks in stamp order through a :class:`navtwin.host.pipeline.Pipeline` built from that meta gives
exactly the live run's estimate lines, byte for byte (the pipeline never reads a clock).

An emulator recording (``navtwin emulate --record DIR``) has device times but no arrival
times. Arrival is then synthesised by :func:`navtwin.host.arrival.arrivals`: the time the chunk's
last byte leaves the UART (8N1), made strictly increasing across ports. Of the two SINS paths
the radio (``xbee``) is used when recorded (:func:`emulator_settings`). That is a deterministic
offline run of the host on the emulated lab; it equals no live run (a live host adds the PTY
and scheduling delays). The in-memory run (:func:`navtwin.lab.run.run_in_memory`) uses the same
rules without the recording, and gives the same lines.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping

from navtwin.protocols import ports as ports_
from navtwin.protocols.ports import DEFAULT_BAUD
from navtwin.protocols.recording import Recording, RecordingError

from . import config as host_config
from .arrival import arrivals
from .config import HostConfig
from .pipeline import Pipeline
from .service import HOST_SOURCE


def is_host_recording(rec: Recording) -> bool:
    return rec.meta.get("source") == HOST_SOURCE and "host" in rec.meta


def _host_meta(rec: Recording) -> dict:
    """The recorded run's settings, checked for shape (one-line errors)."""
    h = rec.meta["host"]
    ok = (isinstance(h, dict) and isinstance(h.get("config"), dict)
          and isinstance(h.get("filters"), list) and all(isinstance(f, str) for f in h["filters"])
          and isinstance(h.get("escaped"), bool) and isinstance(h.get("inputs"), list)
          and h["inputs"] and all(p in ports_.host_inputs() and p in rec.ports for p in h["inputs"]))
    if not ok:
        raise RecordingError(f"{rec.directory / 'recording.json'}: \"host\" is not "
                             f"{{config: object, filters: [names], escaped: bool, inputs: "
                             f"[recorded ports]}}; re-record, or give the config and filters")
    return h


def settings(rec: Recording, *, config: HostConfig | None = None,
             filters: tuple[str, ...] | None = None, escaped: bool | None = None) -> dict:
    """Pipeline keyword arguments for *rec*: the live run's, unless overridden."""
    if is_host_recording(rec):
        h = _host_meta(rec)
        cfg = config or host_config.from_dict(h["config"], f"{rec.directory}: recorded config")
        # the recorded names checked here: a track of a package not installed now
        where = (f"{rec.directory / 'recording.json'}: the recorded filters (override them "
                 "with --filters)")
        for port in h["inputs"]:  # an index without its arrival column, before any estimate
            for c in rec.chunks(port):
                _arrival(rec, c)
                break
        return {"config": cfg, "filters": filters or host_config.parse_filters(h["filters"], where),
                "inputs": tuple(h["inputs"]),
                "escaped": h["escaped"] if escaped is None else escaped}
    ports = rec.meta.get("ports", {})
    readable = ports_.host_inputs()
    if not any(p in rec.ports for p in readable):
        raise RecordingError(f"{rec.directory}: none of the ports {', '.join(readable)} is recorded")
    return emulator_settings(str(rec.meta.get("scenario", "")),
                             {p: ports.get(p, {}) for p in rec.ports},
                             config=config, filters=filters, escaped=escaped)


def config_for(scenario: str) -> str | None:
    """The shipped host config of a scenario's lab: its name, or the name its own starts with
    followed by ``-`` (``corridor-outage`` -> ``corridor``); None if there is none."""
    return next((n for n in host_config.shipped() if scenario == n or scenario.startswith(n + "-")),
                None)


def emulator_settings(scenario: str, ports: Mapping[str, dict], *, config: HostConfig | None = None,
                      filters: tuple[str, ...] | None = None,
                      escaped: bool | None = None) -> dict:
    """Pipeline keyword arguments for a run of the emulator's *scenario* whose *ports* (name ->
    its settings, e.g. ``api_mode``) are at hand: the lab computer's inputs among them (the
    radio's SINS path rather than the direct line), the scenario's shipped config (or the
    default one) and the coordinator's API mode, unless overridden."""
    inputs = [p for p in ports_.host_inputs() if p in ports]
    imu = [p for p in inputs if ports_.get(p).carries_imu]
    for p in imu[1:]:  # one IMU stream: the first in the host's order (the radio's)
        inputs.remove(p)
    if config is None:
        config = host_config.load(config_for(scenario))
    api = next((ports[p]["api_mode"] for p in inputs if "api_mode" in ports[p]), 2)
    return {"config": config, "filters": filters or config.filters, "inputs": tuple(inputs),
            "escaped": (api == 2) if escaped is None else escaped}


def chunks(rec: Recording, inputs: tuple[str, ...]) -> Iterator[tuple[str, bytes, int]]:
    """``(port, bytes, arrival ns)`` in processing order."""
    if is_host_recording(rec):
        for c in rec.merged(list(inputs)):
            yield c.port, c.data, _arrival(rec, c)
        return
    bauds = {p: rec.meta.get("ports", {}).get(p, {}).get("baud", DEFAULT_BAUD) for p in inputs}
    yield from arrivals({p: _device_times(rec, p) for p in inputs}, bauds)


def _arrival(rec: Recording, c) -> int:
    """A host recording's chunk's arrival time: the host stamps every read it records."""
    if c.t_wall_ns is None:
        raise RecordingError(f"{rec.directory}: port {c.port!r} chunk at offset {c.offset} has "
                             "no arrival time (t_wall_ns), which a host recording needs; "
                             "re-record, or restore its index")
    return c.t_wall_ns


def _device_times(rec: Recording, port: str) -> Iterator[tuple[bytes, int]]:
    for c in rec.chunks(port):
        t = c.t_device_ns if c.t_device_ns is not None else c.t_wall_ns
        if t is None:
            raise RecordingError(f"{rec.directory}: port {port!r} chunk at offset {c.offset} "
                                 f"has no time; cannot replay it")
        yield c.data, t


def replay(rec: Recording, emit: Callable[[list], None], *,
           progress: Callable[[float], None] | None = None, make_estimator=None,
           **overrides) -> Pipeline:
    """Run the pipeline over *rec*, calling *emit* with each batch of estimates; returns the
    pipeline (its ``stats()``). *progress* gets the fraction of bytes done, now and then."""
    kw = settings(rec, **overrides)
    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), make_estimator=make_estimator, **kw)
    total = sum(rec.sizes[p] for p in pipe.inputs) or 1
    return drive(pipe, chunks(rec, pipe.inputs), emit, progress, total)


def drive(pipe: Pipeline, chunks: Iterable[tuple[str, bytes, int]],
          emit: Callable[[list], None], progress: Callable[[float], None] | None = None,
          total: int = 1) -> Pipeline:
    """Feed *pipe* the ``(port, bytes, arrival ns)`` *chunks*, then finish it, calling *emit*
    with each batch of estimates; *progress* gets the fraction done of *total* bytes."""
    done = 0
    for n, (port, data, t_ns) in enumerate(chunks):
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
