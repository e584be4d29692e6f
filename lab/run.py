"""The in-memory run: the world -> its UARTs -> the host's pipeline -> estimates, with no PTY
and no file.

The emulator plays the scenario at ``--speed max`` with no ports; its sink hands over each
chunk with its device time; :func:`navtwin.host.arrival.arrivals` stamps it with the time its last
byte reaches the lab computer, and the host's :class:`~host.pipeline.Pipeline`, built as
``navtwin replay`` builds it for an emulator recording (:func:`navtwin.host.replay.emulator_settings`),
turns the chunks into estimates. So the lines equal those of ``navtwin emulate --speed max
--record DIR`` followed by ``navtwin replay DIR``, without the disk in between::

    from navtwin.host.output import estimate_line
    from navtwin.lab.run import run_in_memory

    estimates, pipe = run_in_memory("office", seed=1)
    lines = [estimate_line(e) for e in estimates]

The chunks of the lab computer's inputs are held in memory until the emulation has ended
(about 0.5 MB per minute of the office lab), then fed in arrival order.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from navtwin.emulator.runner import Chunk, Emulation, chunks_together, quick_refusal
from navtwin.emulator.uart import Drained, Irregular
from navtwin.emulator.scenario import Scenario, load_scenario
from navtwin.emulator.imu import shared
from navtwin.emulator.truth import truth_arrays
from navtwin.emulator.world import trajectory_of
from navtwin.host.arrival import arrivals, split
from navtwin.host.pipeline import Pipeline
from navtwin.host import config as host_config
from navtwin.host.replay import config_for, drive, emulator_settings

from .fleet import Follower, followers


def scenario_of(scenario: str | Path | Scenario) -> Scenario:
    """*scenario* itself, or the scenario a name or a file gives."""
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def lab_ports(scenario: str | Path | Scenario, seed: int | None = None, *,
              duration: float | None = None, follower: Follower | None = None,
              **overrides) -> tuple[dict, dict, dict]:
    """The emulation half of :func:`lab_chunks`: the pipeline's keyword arguments, and per
    input port its chunks as arrays, ``{port: (data, sizes, start_ns)}`` (data: the port's
    chunks joined; sizes and device start times int64, one a chunk, in device order) and
    ``{port: baud}``: what :func:`navtwin.host.arrival.arrivals` stamps (the bulk path of
    host.batch.chunks reads the arrays whole)."""
    return lab_ports_together(scenario, [seed], duration=duration, follower=follower,
                              **overrides)[0]


def lab_ports_together(scenario: str | Path | Scenario, seeds, *,
                       duration: float | None = None, follower: Follower | None = None,
                       **overrides) -> list[tuple[dict, dict, dict]]:
    """:func:`lab_ports` of each of *seeds* (a sweep's task), each seed's what it gives
    alone. A scenario without faults takes the emulator's quick path, the seeds' worlds made
    in step (emulator.runner.chunks_together); otherwise each seed runs the timeline."""
    sc = scenario_of(scenario)
    if follower is None and len(sc.fleet) > 1:
        config = overrides.get("config") or host_config.load(config_for(sc.name))
        follower = followers(sc, config, (1,))[0]
    plugged = follower.inputs if follower is not None else {p: p for p in sc.ports}
    if follower is not None:
        overrides = {"config": follower.config, **overrides}
    kw = emulator_settings(sc.name, {i: dict(sc.ports[p]) for i, p in plugged.items()}, **overrides)
    bauds = {i: sc.ports[plugged[i]]["baud"] for i in kw["inputs"]}
    port_of = {i: plugged[i] for i in kw["inputs"]}
    made = None
    if quick_refusal(sc) is None:
        try:  # the lines timed in one pass each, where the runs allow (Emulation.chunks)
            with contextlib.ExitStack() as runs:
                emulations = [runs.enter_context(Emulation(sc, seed, speed=None,
                                                           duration_s=duration, ports=False))
                              for seed in seeds]
                made = chunks_together(emulations, list(port_of.values()))
        except Irregular:  # the timeline's steps, fresh runs
            pass
    if made is None:
        made = [_sunk(sc, seed, duration, port_of.values()) for seed in seeds]
    return [(dict(kw), {i: (got[p].data, np.array(got[p].sizes, np.int64),
                            np.array(got[p].starts, np.int64)) for i, p in port_of.items()},
             bauds) for got in made]


def _sunk(sc: Scenario, seed, duration, ports) -> dict[str, Drained]:
    """The chunks the run of *seed* hands its sink on *ports*, as a drained line's."""
    got: dict[str, tuple[list, list]] = {p: ([], []) for p in ports}

    def sink(chunk: Chunk) -> None:
        taken = got.get(chunk.port)
        if taken is not None:
            taken[0].append(chunk.data)
            taken[1].append(chunk.start_ns)

    with Emulation(sc, seed, speed=None, duration_s=duration, ports=False, sink=sink) as emu:
        emu.run()
    return {p: Drained(b"".join(data), list(map(len, data)), starts)
            for p, (data, starts) in got.items()}


def lab_chunks(scenario: str | Path | Scenario, seed: int | None = None, *,
               duration: float | None = None, follower: Follower | None = None,
               **overrides) -> tuple[dict, Iterator]:
    """The pipeline's keyword arguments for the scenario's lab (``config``, ``filters``,
    ``inputs``, ``escaped``; *overrides* as for :func:`navtwin.host.replay.emulator_settings`) and
    the lab computer's ``(port, bytes, arrival ns)`` in processing order. With several
    vehicles, *follower* (lab.fleet) says which ports a host reads as its inputs, and its
    config; without one, the host follows vehicle 1 (its config's vehicle 1 given vehicle 1's
    tag and router), so a sweep of a scenario with several cars scores car 1."""
    kw, ports, bauds = lab_ports(scenario, seed, duration=duration, follower=follower, **overrides)
    return kw, arrivals(split(ports), bauds)


def run_in_memory(scenario: str | Path | Scenario, seed: int | None = None, *,
                  config=None, filters: tuple[str, ...] | None = None,
                  duration: float | None = None, make_estimator=None,
                  on_innovation=None, follower: Follower | None = None) -> tuple[list, Pipeline]:
    """The host's estimates on the emulated lab of *scenario* and *seed* (the scenario's
    shipped host config and its filters unless *config*/*filters* are given; the whole
    scenario unless *duration* s), and the pipeline (its ``stats()``); *on_innovation* as
    for the :class:`~host.pipeline.Pipeline`; *follower* as for :func:`lab_chunks`."""
    kw, chunks = lab_chunks(scenario, seed, duration=duration, filters=filters, follower=follower,
                            **({} if config is None else {"config": config}))
    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), make_estimator=make_estimator,
                    on_innovation=on_innovation, **kw)
    estimates: list = []
    drive(pipe, chunks, estimates.extend)
    return estimates, pipe


def truth(scenario: str | Path | Scenario, seed: int | None = None, vehicle: int = 1) -> dict:
    """Vehicle *vehicle*'s true ``t`` (s), ``x``, ``y`` (m), ``vx``, ``vy`` (m/s), one row per
    millisecond, as :func:`navtwin.lab.evaluate.load_truth` reads them from the emulator's
    ``truth.csv`` (``truth<n>.csv``). The motion draws nothing, so *seed* changes nothing
    (within emulator.imu.shared_truth, a sweep's task, it is made once)."""
    sc = scenario_of(scenario)
    if not 1 <= vehicle <= len(sc.fleet):
        raise ValueError(f"vehicle {vehicle}: scenario {sc.name} has vehicles 1..{len(sc.fleet)}")
    motion = trajectory_of(sc.fleet[vehicle - 1])

    def columns():  # each its own array: np.interp copies a column of the rows at every call
        tr = truth_arrays(motion, 0, sc.duration_ns)
        return tr["t"] / 1e9, *(np.ascontiguousarray(tr[f]) for f in ("x", "y", "vx", "vy"))

    return dict(zip(("t", "x", "y", "vx", "vy"),
                    shared(("truth", motion.key, sc.duration_ns), columns)))
