"""Entry points of installed packages, read once per process for every registry.

The registries (``navtwin.commands``, ``navtwin.faults``, ``navtwin.tracks``,
``navtwin.benchmarks``) each name a group. importlib.metadata reads every installed package's
entry_points.txt whichever group is asked for (``entry_points(group=...)`` selects after the
full read), about 2-4 ms a time, so one read serves every group of the process. A change of
``sys.path`` (a package added at run time, as a test does) reads again.
"""
from __future__ import annotations

import functools
import sys
from importlib import metadata


def entry_points(group: str) -> tuple:
    """The entry points of *group* in every installed package, sorted by name."""
    return _by_group(tuple(sys.path)).get(group, ())


@functools.lru_cache(maxsize=1)
def _by_group(path: tuple[str, ...]) -> dict[str, tuple]:
    every = metadata.entry_points()  # one read of every package (selects from it do not read)
    return {group: tuple(sorted(every.select(group=group), key=lambda ep: ep.name))
            for group in every.groups}
