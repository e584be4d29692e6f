"""The host through faults: an IMU stream that stops (an RF link fade) is bridged when the
gap is short and re-initialises the fusion tracks when it is long; the tracks are back
within their normal error soon after. In memory (lab.run), against the world's truth."""
import numpy as np
import pytest

from navtwin.emulator.world import World
from navtwin.host.output import estimate_line
from navtwin.lab import evaluate
from navtwin.lab.run import run_in_memory

from ..emulator.world_helpers import variant

FUSION = ("kf", "ekf", "ukf")
SEED = 4


def _errors(sc, seed=SEED):
    estimates, pipe = run_in_memory(sc, seed)
    w = World(sc, seed)
    tr = w.truth(0, w.duration_ns)
    truth = {"t": tr["t"] / 1e9, "x": tr["x"], "y": tr["y"]}
    by = evaluate.load_estimates(map(estimate_line, estimates))
    return {n: (e["t"], evaluate.error(truth, e)) for n, e in by.items()}, pipe


def _fade(tmp_path, start, end):
    return variant(tmp_path, "office", f'[[faults]]\nkind = "link_fade"\nstart_s = {start}\n'
                                       f'end_s = {end}\nattempt_loss = 1.0\n', name=f"fade{end}")


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return _errors(variant(tmp_path_factory.mktemp("clean"), "office", ""))


def test_a_long_imu_gap_re_initialises_the_fusion_tracks_and_they_recover(tmp_path, clean):
    errors, pipe = _errors(_fade(tmp_path, 20.0, 22.0))
    st = pipe.stats()["vehicles"][0]["estimator"]
    assert st["imu_gaps"]["reinit"] == 1
    for name in FUSION:
        assert st["reinit"][name] == {"gap": 1}, st["reinit"]
    assert st["reinit"]["sins"] == {"gap": 1} and "wsn" not in st["reinit"]
    recovery = {}
    for name in FUSION:
        t0, e0 = clean[0][name]
        bound = max(2.0 * float(np.percentile(e0[t0 >= 10], 95)), float(e0[t0 >= 10].max()))
        t, e = errors[name]
        over = (t >= 22.0) & (e >= bound)
        recovery[name] = round(float(t[over].max()) - 22.0 + 0.1, 1) if over.any() else 0.0
        assert recovery[name] < 2.0, (name, recovery)  # back within the clean run's bound
        assert not ((t >= 24.0) & (e >= bound)).any(), name
    print(f"\nlink fade 2 s: recovery after the fade (s) {recovery}")


def test_a_short_imu_gap_is_bridged_and_changes_no_track_beyond_its_normal_error(tmp_path, clean):
    errors, pipe = _errors(_fade(tmp_path, 20.0, 20.2))
    st = pipe.stats()["vehicles"][0]["estimator"]
    assert st["imu_gaps"]["bridged"] >= 1 and st["imu_gaps"]["reinit"] == 0
    assert st["reinit"] == {}
    for name in FUSION:
        t0, e0 = clean[0][name]
        t, e = errors[name]
        assert float(e[t >= 10].max()) < max(2.0 * float(np.percentile(e0[t0 >= 10], 95)),
                                             float(e0[t0 >= 10].max())), name
