"""The NLOS/multipath range error (emulator.multipath, [ranging.multipath]): its statistics
against its parameters over many seeds, and its place in the exchanges."""
import math

import numpy as np
import pytest

from navtwin.emulator.multipath import Multipath
from navtwin.emulator.scenario import Multipath as Spec
from navtwin.emulator.world import World

from .world_helpers import reports, run, true_distances, variant

SEEDS = range(400)


def test_field_has_its_sigma_and_squared_exponential_correlation():
    """Over 400 seeds: var g(p) = field_sigma^2 and corr(g(p), g(p + r)) = exp(-r^2 / 2L^2)
    at r = 0.5, 1, 2, 4 L (4 standard errors; the correlation's is about (1 - rho^2)/sqrt(n))."""
    spec = Spec(enabled=True, field_sigma_m=0.2, corr_length_m=1.5)
    lags = np.array([0.0, 0.75, 1.5, 3.0, 6.0])
    p = np.column_stack((3.0 + lags, np.full(len(lags), -1.0)))
    g = np.array([Multipath(spec, 1, seed).field(p) for seed in SEEDS])
    n = len(SEEDS)
    assert np.std(g[:, 0]) == pytest.approx(0.2, abs=4 * 0.2 / math.sqrt(2 * n))
    assert abs(np.mean(g[:, 0])) < 4 * 0.2 / math.sqrt(n)
    for j, r in enumerate(lags[1:], 1):
        rho = math.exp(-r * r / (2 * 1.5**2))
        got = np.corrcoef(g[:, 0], g[:, j])[0, 1]
        assert got == pytest.approx(rho, abs=4 * (1 - rho**2) / math.sqrt(n) + 0.02), r


def test_field_is_fixed_per_seed_and_differs_between_anchors():
    spec = Spec(enabled=True)
    p = np.array([[1.0, 2.0], [5.0, -1.0]])
    assert np.array_equal(Multipath(spec, 1, 7).field(p), Multipath(spec, 1, 7).field(p))
    assert not np.allclose(Multipath(spec, 1, 7).field(p), Multipath(spec, 2, 7).field(p))


def test_drift_is_gauss_markov_with_its_sigma_and_correlation_time():
    """Exchanges every 0.1 s for 60 s, 400 seeds: sd drift_sigma at every time (started from
    the stationary law), lag correlation exp(-dt / tau) at 1, 5, 20 s."""
    spec = Spec(enabled=True, drift_sigma_m=0.1, drift_corr_s=5.0)
    t = np.arange(600) * 100_000_000
    b = np.array([Multipath(spec, 3, seed).drift(t) for seed in SEEDS])
    n = len(SEEDS)
    for k in (0, 299, 599):
        assert np.std(b[:, k]) == pytest.approx(0.1, abs=4 * 0.1 / math.sqrt(2 * n))
    for lag_s in (1.0, 5.0, 20.0):
        k = round(lag_s * 10)
        rho = math.exp(-lag_s / 5.0)
        got = np.mean([np.corrcoef(b[:, i], b[:, i + k])[0, 1] for i in (0, 100, 200)])
        assert got == pytest.approx(rho, abs=4 * (1 - rho**2) / math.sqrt(n) + 0.02), lag_s


def test_drift_does_not_depend_on_how_the_exchanges_are_batched():
    spec = Spec(enabled=True)
    t = np.arange(50) * 100_000_000
    whole = Multipath(spec, 1, 3).drift(t)
    parts = Multipath(spec, 1, 3)
    assert np.array_equal(np.concatenate([parts.drift(t[:7]), parts.drift(t[7:30]),
                                          parts.drift(t[30:])]), whole)


NOISELESS = """
duration_s = 30.0
[ranging]
sigma0_m = 0.0
sigma_per_m = 0.0
reply_jitter_ns = 0.0
[trajectory]
alignment_s = 40.0
[ranging.multipath]
enabled = true
"""


def test_exchanges_carry_the_models_error(tmp_path):
    """Corridor, tag at rest, white noise off: each anchor's range error minus c_i and the
    scale factor's is the field at the start (constant) plus the drift; with the drift off
    it is constant, and equal to the field the model gives at the tag's position."""
    sc = variant(tmp_path, "corridor", NOISELESS + "drift_sigma_m = 0.0\n")
    w, events = run(sc)
    r = reports(events)
    truth = true_distances(w, sc, r)
    for a in sc.anchors:
        m = r["anchor"] == a.id
        eps = r["d"][m] - (sc.ranging.scale * truth[m] + a.range_bias_m)
        expected = Multipath(sc.ranging.multipath, a.id, sc.seed).field(np.array([[0.0, 0.0]]))[0]
        assert np.allclose(eps, expected, atol=2e-3), a.id
    drifting = variant(tmp_path, "corridor", NOISELESS, name="drifting")
    w, events = run(drifting)
    r = reports(events)
    truth = true_distances(w, drifting, r)
    m = r["anchor"] == 1
    eps = r["d"][m] - (drifting.ranging.scale * truth[m] + 0.25)
    assert np.std(eps) > 0.01 and np.max(np.abs(np.diff(eps))) < 0.1  # slow, not white


def test_multipath_world_is_independent_of_slicing(tmp_path):
    sc = variant(tmp_path, "corridor", "duration_s = 5.0\n")
    whole = World(sc).advance(10**12)
    w, got, t = World(sc), [], 0
    rng = np.random.default_rng(5)
    while t < sc.duration_ns:
        t += int(rng.integers(1, 300_000_000))
        got += w.advance(t)
    assert got + w.advance(10**12) == whole
