"""The opt-in innovation output: the same estimates, byte for byte, with and without it, and
one line per gated fusion update whose NIS is what the track's filter computed."""
import json
from collections import Counter

import numpy as np
from scipy.stats import chi2

from navtwin.host.output import INNOVATION_KEYS, estimate_line, innovation_line
from navtwin.lab.run import run_in_memory


def test_innovations_change_no_estimate_and_count_every_update():
    plain, _ = run_in_memory("office", seed=5, duration=20.0)
    lines = []
    with_inn, pipe = run_in_memory("office", seed=5, duration=20.0,
                                   on_innovation=lambda *f: lines.append(innovation_line(*f)))
    assert [estimate_line(e) for e in with_inn] == [estimate_line(e) for e in plain]
    rows = [json.loads(x) for x in lines]
    assert rows and all(tuple(r) == INNOVATION_KEYS for r in rows)
    st = pipe.stats()["vehicles"][0]["estimator"]
    for track in ("kf", "ekf", "ukf"):
        mine = [r for r in rows if r["filter"] == track]
        # every update the track counts (accepted) and every one its gate rejected is a line
        accepted = Counter(r["kind"] for r in mine if r["accepted"])
        assert dict(accepted) == st["updates"][track], track
        assert sum(not r["accepted"] for r in mine) == st["rejections"][track].get("gate", 0) + \
            st["rejections"][track].get("gate_reopened", 0)
        assert {r["vehicle"] for r in mine} == {1}
        # the position updates' NIS: chi-square of their dimension, near its mean
        pos = [r for r in mine if r["kind"] in ("fix", "tdoa")]
        dim = pos[0]["dim"]
        assert dim == (2 if track == "kf" else 3)
        nis = np.array([r["nis"] for r in pos])
        assert 0.2 * dim < nis.mean() < 5 * dim
        assert (nis > chi2.ppf(0.9999, dim)).sum() == sum(not r["accepted"] for r in pos)
