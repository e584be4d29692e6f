"""A convoy: vehicle 1 of a scenario repeated (``navtwin emulate --vehicles N``, the demo).

``convoy(sc, n)`` is *sc* with vehicles 2..n added as ``[[vehicles]]`` tables (emulator.scenario)
that copy vehicle 1's tables except what must differ between two cars on one lab:

- the tag id: the next ids after vehicle 1's that no anchor and no other tag uses (ids past 254
  make the gateway write its wide reports, protocols.nanoloc);
- the router's serial number low half ``SL``: vehicle 1's + (n - 1) (the high half, Digi's
  OUI, stays);
- the start: the same taped line, each car leaving ``gap_s`` after the one before it (a
  longer stationary alignment), so they drive it in a queue instead of on top of each other.

*network* sets both ``[xbee] network`` and ``[ranging] network`` (``shared``: one coordinator
and one TDMA for every car; ``per-vehicle``: a coordinator, network and ports per car); a
scenario file mixes them.
"""
from __future__ import annotations

import dataclasses

from .scenario import MAX_VEHICLES, NETWORKS, Scenario, ScenarioError

GAP_S = 2.0  # between two cars leaving the start
SL_MAX = 0xFFFFFFFF


def convoy(sc: Scenario, n: int, *, network: str | None = None, gap_s: float = GAP_S) -> Scenario:
    """*sc* with *n* vehicles in all (module doc); ScenarioError (one line) if it cannot hold them."""
    if not 1 <= n <= MAX_VEHICLES:
        raise ScenarioError(f"vehicles: {n} is outside 1..{MAX_VEHICLES}; give a number in that range")
    if network is not None and network not in NETWORKS:
        raise ScenarioError(f"network: {network!r} is not one of {', '.join(NETWORKS)}; use one of them")
    first, *more = sc.fleet
    if more:
        raise ScenarioError(f"vehicles: scenario {sc.name} already has {len(sc.fleet)} vehicles; "
                            "make a convoy of a one-vehicle scenario, or add [[vehicles]] tables")
    if first.router.SL + n - 1 > SL_MAX:
        raise ScenarioError(f"vehicles: vehicle 1's router SL {first.router.SL:#X} leaves no room for "
                            f"{n - 1} more; lower [xbee.router] SL")
    taken = set(sc.anchor_ids) | {first.tag.id}
    ids, tag = [], first.tag.id
    while len(ids) < n - 1:
        tag += 1
        if tag > 0xFFFF:
            raise ScenarioError(f"vehicles: no {n - 1} free tag ids after {first.tag.id}; lower [tag] id")
        if tag not in taken:
            ids.append(tag)
    vehicles = tuple(dataclasses.replace(
        first, tag=dataclasses.replace(first.tag, id=ids[k - 1]),
        router=dataclasses.replace(first.router, SL=first.router.SL + k),
        trajectory=dataclasses.replace(first.trajectory,
                                       alignment_s=first.trajectory.alignment_s + k * gap_s))
        for k in range(1, n))
    xbee, ranging = sc.xbee, sc.ranging
    if network is not None:
        xbee = dataclasses.replace(xbee, network=network)
        ranging = dataclasses.replace(ranging, network=network)
    return dataclasses.replace(sc, vehicles=vehicles or None, xbee=xbee, ranging=ranging)
