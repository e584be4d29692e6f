"""Paper 001's tracks on the emulated corridor-outage (anchor 2 silent 18-23 s and 40-45 s),
in memory against the world's truth: lc drifts while the anchor is silent, tc and fatci hold."""
import math

import numpy as np
import pytest

from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.world import World
from navtwin.lab.run import run_in_memory

OUTAGES = ((18.0, 23.0), (40.0, 45.0))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_on_corridor_outage_every_001_track_holds_while_anchor_2_is_silent(seed):
    estimates, _ = run_in_memory("corridor-outage", seed, filters=("lc", "tc", "fatci"))
    w = World(load_scenario("corridor-outage"), seed)
    truth = w.truth(0, w.duration_ns)
    tt = truth["t"] * 1e-9
    worst = {}
    for e in estimates:
        if any(a <= e.t <= b for a, b in OUTAGES):
            err = math.hypot(e.x - np.interp(e.t, tt, truth["x"]), e.y - np.interp(e.t, tt, truth["y"]))
            worst[e.filter] = max(worst.get(e.filter, 0.0), err)
    # tc and fatci take the three ranges; lc the three anchors' TDOA fixes, their mirror
    # positions told apart by the plausible region and the previous fix (001's LC had no fix
    # and drifted to 1.49 m; ours drifted to 3 m when rounding chose the mirror)
    assert worst["tc"] < 1.0 and worst["fatci"] < 1.0, worst
    assert worst["lc"] < 1.5, worst
