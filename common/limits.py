"""Ranges that the command line, the scenario files and the host config all check.

Written once here (``protocols`` imports nothing of ours, so the emulator and the host can
both use it): a number is accepted only when it is finite and inside its range, so that no
nan, inf or 1e300 reaches arithmetic that overflows, loops forever or hangs up a line.
"""
from __future__ import annotations

import math
import sys

#: nanoLOC node ids as the gateway reports them (anchors and tags).
ANCHOR_IDS = (1, 254)
#: The lab, in metres: plan coordinates and sizes (a room, a hall, a campus at most), heights.
MAX_COORD_M = 100_000.0
MAX_HEIGHT_M = 1000.0
#: The site and the range model (c_i and f of paper 001 eq. 13), as surveyed or calibrated.
LATITUDE_DEG = (-90, 90)
LONGITUDE_DEG = (-180, 180)
#: m, ellipsoid heights of a site or an anchor: the Dead Sea shore to above Everest.
ELLIPSOID_HEIGHT_M = (-500, 9000)
GRAVITY_M_S2 = (9.7, 9.9)
RANGE_BIAS_M = (-5, 5)
RANGE_SCALE = (0.5, 1.5)
#: Run seeds: TOML integers are 64-bit signed.
SEEDS = (0, 2**63 - 1)
#: ``--speed`` factors of the emulator (faster: ``--speed max``).
SPEEDS = (0.01, 10000.0)
#: Longest run, emulated or live, in seconds (about 115 days; ns counts stay far inside int64).
MAX_DURATION_S = 10_000_000
#: Seeds one batch-engine task of a sweep holds (lab.batch), and the default at most: a larger
#: batch shares each record's numpy calls among more seeds, at about 4 MB a seed of office
#: (fewer by default where a worker's memory holds fewer: lab.sweep.batch_size_for).
BATCH_SEEDS = (1, 4096)
BATCH_SIZE = 512
#: vehicle numbers of a scenario: 256 vehicles' ports are 768 PTYs, a fifth of Linux's
#: default kernel.pty.max
VEHICLES = (1, 256)
#: how several vehicles share a radio network (a scenario's [xbee] and [ranging] network)
NETWORKS = ("shared", "per-vehicle")


def show(v) -> str:
    """A bound or value as messages write it: 1000000 stays an integer, 0.5 as %g."""
    return str(v) if isinstance(v, int) else f"{v:g}"


def span(lo, hi, above: bool = False) -> str:
    """``in [lo, hi]`` (``in (lo, hi]`` when *above*); ``>= lo`` or ``> lo`` with no upper
    bound; ``<= hi`` with no lower one."""
    if hi == math.inf:
        return f"{'>' if above else '>='} {show(lo)}"
    if lo == -math.inf:
        return f"<= {show(hi)}"
    return f"in {'(' if above else '['}{show(lo)}, {show(hi)}]"


def finite(value: int | float) -> bool:
    """Whether *value* is a finite float; an int past the float range (TOML integers have any
    number of digits) is not, where math.isfinite would raise OverflowError."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def limit_problem(e: Exception) -> str:
    """The limit a TOML parser hit beyond its syntax, in one line: nesting deeper than the
    recursion limit, or (ValueError) an integer of more digits than Python converts."""
    if isinstance(e, RecursionError):
        return "arrays or tables nested too deeply"
    return f"an integer of more than {sys.get_int_max_str_digits()} digits"
