"""Models run together: a sweep's seeds of one vehicle or one network step along a seed axis
(emulator.imu.generate_together, board.Board.frames_together,
nanoloc.NanolocNetwork.reports_together), each seed's numbers as it makes them alone."""
from __future__ import annotations


def alike(keys: list) -> list[list[int]]:
    """The indices of *keys* in groups of equal key, in order of first appearance, each
    group in index order; a None key (a model that runs alone) is a group of its own."""
    groups: dict = {}
    for i, key in enumerate(keys):
        groups.setdefault(("alone", i) if key is None else ("key", key), []).append(i)
    return list(groups.values())
