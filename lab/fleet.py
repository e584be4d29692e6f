"""The lab computer's side of a lab with several vehicles: which host follows which vehicles,
on which ports, with which config.

The host runs unchanged on real hardware: it reads the ports it is given and routes what it
reads by the router address and tag id of each vehicle in its config (host.pipeline). So a
lab of N vehicles is followed by

- one host on the coordinator's and the gateway's ports (``xbee``, ``nanoloc``) whose config
  lists every followed vehicle, when the vehicles share the air (``[xbee] network`` and
  ``[ranging] network`` shared): it skips the other vehicles' frames, counted as
  ``imu_other_router`` and ``reports_other_tag``; or
- one host per followed vehicle on that vehicle's ports (``xbee<n>``, ``nanoloc<n>``) when each
  vehicle has networks of its own (both ``per-vehicle``).

A lab that shares one network and not the other has no such split (one host cannot read a
port another host holds), and is refused. Each followed vehicle's entry in a host config is
the lab config's vehicle 1 moved with the vehicle: its start shifted by the difference of
the two taped lines' starts and its heading turned by the difference of their first legs,
with the vehicle's own tag id and router address (SH + SL, as the host config writes it).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from navtwin.emulator.scenario import Scenario
from navtwin.host.config import HostConfig
from navtwin.protocols import ports


class FleetError(ValueError):
    """A fleet the lab cannot follow as asked: one line naming the fix."""


@dataclass(frozen=True)
class Follower:
    """One host of the lab: its number (1 first), the scenario's vehicles it follows (in
    its config's vehicle order), its inputs (host input -> the port instance it reads) and
    its config."""

    number: int
    vehicles: tuple[int, ...]
    inputs: dict[str, str]
    config: HostConfig


def _heading_deg(waypoints) -> float:
    (x0, y0), (x1, y1) = waypoints[0], waypoints[1]
    return math.degrees(math.atan2(y1 - y0, x1 - x0))


def host_vehicle(sc: Scenario, config: HostConfig, n: int):
    """The host config's vehicle entry for the scenario's vehicle *n* (module doc)."""
    first, mine, base = sc.fleet[0], sc.fleet[n - 1], config.vehicles[0]
    (x0, y0), (x1, y1) = first.trajectory.waypoints[0], mine.trajectory.waypoints[0]
    turn = _heading_deg(mine.trajectory.waypoints) - _heading_deg(first.trajectory.waypoints)
    heading = (base.heading_deg + turn + 180.0) % 360.0 - 180.0
    return dataclasses.replace(base, start=(base.start[0] + x1 - x0, base.start[1] + y1 - y0),
                               heading_deg=heading, tag=mine.tag.id,
                               router=f"{mine.router.SH:08X}{mine.router.SL:08X}")


def followers(sc: Scenario, config: HostConfig, vehicles: tuple[int, ...] | None = None,
              inputs: tuple[str, ...] = (ports.XBEE.name, ports.NANOLOC.name)) -> list[Follower]:
    """The hosts that follow *vehicles* (default all) of *sc* (module doc), each reading its
    *inputs* (the host inputs it is given; the direct ``sins`` line is a vehicle's own)."""
    n = len(sc.fleet)
    vehicles = tuple(range(1, n + 1)) if vehicles is None else tuple(vehicles)
    if not vehicles or any(not 1 <= v <= n for v in vehicles) or len(set(vehicles)) < len(vehicles):
        raise FleetError(f"vehicles: {list(vehicles)} is not a list of distinct vehicles of 1..{n}; "
                         "name the scenario's vehicles to follow")
    if n == 1:  # the lab as it always was: the config as it is
        return [Follower(1, (1,), {i: i for i in inputs}, config)]
    shared = {sc.units(ports.get(i).unit) == 1 for i in inputs if ports.get(i).unit != "vehicle"}
    if len(shared) > 1:
        raise FleetError("the vehicles share one of the coordinator and the gateway and not the other; "
                         "give [xbee] and [ranging] the same network (both shared or both per-vehicle)")

    def config_of(which: tuple[int, ...]) -> HostConfig:
        lab = dataclasses.replace(config.lab, vehicles=tuple(host_vehicle(sc, config, v) for v in which))
        return dataclasses.replace(config, lab=lab)

    if shared == {True}:
        return [Follower(1, vehicles, {i: i for i in inputs}, config_of(vehicles))]
    return [Follower(k, (v,), {i: ports.instance(i, v) for i in inputs}, config_of((v,)))
            for k, v in enumerate(vehicles, 1)]
