"""001's range calibration on the emulated lab: the calibration walk in memory, its step
table, and the corridor's WSN-only error with and without the result.

The host side (host.calibration) fits from the gateway's bytes and a step table; here the
emulator supplies both: the bytes of a scenario run in memory (or a recording's), and the
step table a lab user would survey, read off the scenario's stepped trajectory
(:func:`step_table`; shipped as host/calibrations/corridor-steps.toml). :func:`seed_figures`
is one seed's figures of ``navtwin calibrate --seeds``'s table.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from navtwin.emulator.runner import Chunk, Emulation
from navtwin.emulator.scenario import Scenario, load_scenario
from navtwin.emulator.trajectory import SteppedProfile, Trajectory
from navtwin.emulator.world import World
from navtwin.host import calibration as cal
from navtwin.host.config import HostConfig
from navtwin.protocols.ports import NANOLOC
from navtwin.protocols.recording import Recording

from .evaluate import error
from .run import run_in_memory

MARGIN_S = 0.25  # after the tag has come to rest, and before it moves again


def _scenario(scenario) -> Scenario:
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def step_table(scenario, exchanges: int = 20) -> cal.StepTable:
    """The surveyed points of a stepped scenario and, in gateway time, the last *exchanges*
    cycles of each rest but MARGIN_S (a rest must be long enough for them)."""
    sc = _scenario(scenario)
    tr = Trajectory(sc.trajectory, sc.tag.z)
    if not isinstance(tr.speed, SteppedProfile):
        raise ValueError(f"scenario {sc.name}: [trajectory] step_m is 0; a calibration walk "
                         "rests at its points: set step_m and dwell_s")
    window = exchanges * sc.ranging.cycle_ms / 1e3
    network = 1 + sc.clocks.network_ppm * 1e-6
    steps = []
    for start, end, s in tr.speed.rests():
        end = min(end, sc.duration_s)
        if end - start < window + 2 * MARGIN_S:
            raise ValueError(f"scenario {sc.name}: the rest at {start:g} s is shorter than "
                             f"{window + 2 * MARGIN_S:g} s; lengthen dwell_s or duration_s")
        p = tr.path.evaluate(np.array([s]))[0][0]
        steps.append(cal.Step(x=round(float(p.real), 6), y=round(float(p.imag), 6),
                              start_s=round((end - MARGIN_S - window) * network, 6),
                              end_s=round((end - MARGIN_S) * network, 6)))
    return cal.StepTable(exchanges=exchanges, steps=tuple(steps))


def gateway_bytes(scenario, seed: int | None = None) -> bytes:
    """The gateway's serial output of a run of *scenario*, in memory."""
    out: list[bytes] = []

    def sink(chunk: Chunk) -> None:
        if chunk.port == NANOLOC.name:
            out.append(chunk.data)

    with Emulation(_scenario(scenario), seed, speed=None, ports=False, sink=sink) as emu:
        emu.run()
    return b"".join(out)


def recorded_bytes(directory: str | Path) -> bytes:
    """The gateway's bytes of a recording (emulator's or host's)."""
    return Recording(directory).read_bytes(NANOLOC.name)


def calibrate(data: bytes, steps: cal.StepTable, config: HostConfig, sigma_degree: int = 2) -> cal.Result:
    """host.calibration.fit on the gateway bytes with the config's anchor survey."""
    v = config.vehicles[0]
    return cal.fit(cal.ranges(data), steps, config.anchors, v.tag_height, sigma_degree)


def wsn_errors(scenario, seed: int | None, config: HostConfig,
               calibration: cal.Calibration | None) -> dict:
    """The ``wsn`` track's position error (m) on a run of *scenario* against the emulator's
    truth, with *config* and *calibration* (None: the ranges uncorrected): max, variance,
    mean."""
    config = dataclasses.replace(config, calibration=calibration)
    sc = _scenario(scenario)
    estimates, _ = run_in_memory(sc, seed, config=config, filters=("wsn",))
    w = World(sc, seed)
    truth = w.truth(0, w.duration_ns)
    t = np.array([e.t for e in estimates if e.filter == "wsn"])
    e = {"t": t, "x": np.array([e.x for e in estimates if e.filter == "wsn"]),
         "y": np.array([e.y for e in estimates if e.filter == "wsn"])}
    keep = t <= truth["t"][-1] / 1e9
    err = error({"t": truth["t"] / 1e9, "x": truth["x"], "y": truth["y"]},
                {k: v[keep] for k, v in e.items()})
    return {"max": float(err.max()), "variance": float(err.var()), "mean": float(err.mean()),
            "n": len(err)}


def seed_figures(scenario, seed: int | None, steps: cal.StepTable, config: HostConfig,
                 sigma_degree: int = 2, evaluate=None) -> dict[str, tuple[float, float]]:
    """One seed's (before, after) figures: of the walk of *scenario* fitted (``scale`` f, NaN
    before; ``range`` the mean range error; ``wsn_max``, ``wsn_variance`` at the points) and,
    with *evaluate* (a moving scenario), of its wsn track uncorrected and with this seed's
    calibration (``eval_max``, ``eval_variance``, ``eval_mean``: :func:`wsn_errors`)."""
    result = calibrate(gateway_bytes(scenario, seed), steps, config, sigma_degree)
    figures = {"scale": (math.nan, result.calibration.scale), "range": result.range_error_m,
               "wsn_max": result.wsn_max_m, "wsn_variance": result.wsn_variance_m2}
    if evaluate is not None:
        runs = [wsn_errors(evaluate, seed, config, k) for k in (None, result.calibration)]
        figures.update({f"eval_{k}": (runs[0][k], runs[1][k]) for k in ("max", "variance", "mean")})
    return figures
