"""The tightly coupled tracks' batch twins (host.batch.tracks.ekf, ukf): each seed's
estimates equal the per-seed tracks', with the ranges measured per cycle (tdoa) or each on
its own (toa), on seeds of every shipped scenario, without a seed leaving the batch for
them (a track gated out, as on rssi-centroid, starts again at a fix there too); and their
parts (host.batch.model's ranges, host.batch.ukf's update) equal the per-seed ones seed by
seed."""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest

from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.shipped import NAMES
from navtwin.host.batch.estimator import BatchEstimator, Unbatchable, stream
from navtwin.host.batch.model import BatchRanges
from navtwin.host.batch.ukf import unscented_correct
from navtwin.host.filters import ConstantAcceleration, Ranges, UnscentedKalmanFilter
from navtwin.host.filters.ukf import merwe_weights
from navtwin.host.measurements import Range, Tdoa
from navtwin.host.tracks.fusion import TightSettings
from navtwin.host.tracks.ukf import UkfSettings
from navtwin.host.wsn import AnchorLayout, tdoa_covariance
from navtwin.lab import batch
from navtwin.lab.run import run_in_memory

from .test_batch import DURATION_S, SEEDS, assert_equal

TIGHT = ("ekf", "ukf")
FILTERS = ("sins", "wsn", "kf", *TIGHT)


@pytest.mark.parametrize("scenario", NAMES)
def test_each_seed_equals_the_in_memory_run(scenario):
    """The shipped settings (tight = "tdoa" unless a host config says otherwise)."""
    sc = load_scenario(scenario)
    out = batch.run(sc, SEEDS, filters=FILTERS, duration=DURATION_S)
    assert set(TIGHT) <= set(out.batched)
    for seed, got in zip(SEEDS, out.estimates):
        est, _ = run_in_memory(sc, seed, filters=FILTERS, duration=DURATION_S)
        assert_equal(batch.columns(est, FILTERS), got, f"{scenario} seed {seed}")
    assert not [why for why in out.ejected.values() if why.split(":")[0] in ("kf", *TIGHT)]
    if scenario == "office":
        assert out.ejected == {}


@lru_cache(maxsize=None)
def _records(scenario: str, seed: int):
    return batch.records(scenario, seed, filters=FILTERS, duration=DURATION_S)


def _tight(cfg, tight: str):
    """*cfg* with both tracks' ``tight`` set (as [filters.ekf] and [filters.ukf] would)."""
    own = dict(cfg.settings)
    own["ekf"] = replace(own.get("ekf") or TightSettings(), tight=tight)
    own["ukf"] = replace(own.get("ukf") or UkfSettings(), tight=tight)
    return replace(cfg, settings=own)


@pytest.mark.parametrize("tight", ["toa", "tdoa"])
@pytest.mark.parametrize("scenario", NAMES)
def test_both_range_measurements_equal_the_per_seed_tracks(scenario, tight):
    """The seeds stacked in one engine, each equal to the estimator fed its records alone
    (which is the in-memory run's: tests/lab/test_batch.py)."""
    taken = [_records(scenario, seed) for seed in SEEDS]
    cfg = _tight(replace(taken[0][0], filters=FILTERS), tight)
    takes = BatchEstimator(cfg, 0).takes()
    assert (Range if tight == "toa" else Tdoa) in takes
    streams, seeds = [], []
    for seed, (_, recs) in zip(SEEDS, taken):
        try:
            streams.append(stream(recs, takes, frozenset(), cfg.imu_gap_s))
            seeds.append(seed)
        except Unbatchable:  # its records leave the common path (lab.batch runs it per seed)
            assert scenario != "office"
    engine = BatchEstimator(cfg, len(seeds))
    estimates = engine.run(streams)
    assert engine.ejected == {}  # a track gated out starts again at a fix in the batch too
    for seed, got in zip(seeds, estimates):
        recs = taken[SEEDS.index(seed)][1]
        assert_equal(batch.columns(batch.per_seed(cfg, recs), FILTERS), got,
                     f"{scenario} {tight} seed {seed}")
    if scenario == "office":
        assert len(seeds) == len(SEEDS)


LAYOUT = AnchorLayout({1: (0.0, 0.0, 2.5), 2: (12.0, 0.0, 2.4), 3: (12.0, 8.0, 2.6),
                       4: (0.0, 8.0, 2.5), 5: (6.0, 4.0, 3.0)}, tag_height=0.3)


def _seeds(rng, n):
    """n states (position, velocity, acceleration) and positive definite covariances."""
    x = np.column_stack((rng.uniform(1, 11, (n, 2)), rng.normal(0, 1, (n, 2)),
                         rng.normal(0, 0.5, (n, 2))))
    A = rng.normal(0, 0.3, (n, 6, 6))
    return x, np.matmul(A, np.swapaxes(A, 1, 2)) + 0.05 * np.eye(6)


@pytest.mark.parametrize("reference", [None, 3])
def test_the_ranges_of_each_seed_are_its_own(reference):
    """h, h at sigma points and the Jacobian of host.batch.model.BatchRanges equal
    host.filters.model.Ranges of each seed, bit for bit."""
    rng = np.random.default_rng(3)
    n, anchors = 9, (3, 1, 5, 4)
    x, _ = _seeds(rng, n)
    lags = rng.uniform(0, 0.08, (n, len(anchors)))
    ref = None if reference is None else anchors.index(reference)
    got = BatchRanges.of(LAYOUT, LAYOUT.index(anchors), lags, ref)
    hx, J = got.linearize(x)
    Z = got.h(np.stack([x, 2 * x], 1))
    for i in range(n):
        one = Ranges(LAYOUT, anchors, lags[i].tolist(), reference)
        h1, J1 = one.linearize(x[i])
        assert np.array_equal(hx[i], h1) and np.array_equal(J[i], J1)
        assert np.array_equal(Z[i], one.h(np.stack([x[i], 2 * x[i]])))
    assert got.dim == one.dim == hx.shape[1]


@pytest.mark.parametrize("toa", [True, False])
def test_the_unscented_update_of_each_seed_is_its_filters(toa):
    """host.batch.ukf.unscented_correct equals UnscentedKalmanFilter.update of each seed, the
    gated-out seeds unchanged."""
    rng = np.random.default_rng(4)
    n = 12
    x, P = _seeds(rng, n)
    model = ConstantAcceleration(0.5)
    if toa:  # one range each, to an anchor of its own
        rows = rng.integers(0, 5, n)
        lags = rng.uniform(0, 0.05, n)
        meas = [Ranges(LAYOUT, (LAYOUT.ids[r],), (lag,)) for r, lag in zip(rows, lags)]
        got_meas = BatchRanges.of(LAYOUT, rows[:, None], lags[:, None])
        R = np.array([[0.09]])
    else:
        anchors = (1, 2, 3, 4)
        lags = rng.uniform(0, 0.05, (n, 4))
        meas = [Ranges(LAYOUT, anchors, lag.tolist(), reference=1) for lag in lags]
        got_meas = BatchRanges.of(LAYOUT, LAYOUT.index(anchors), lags, 0)
        R = tdoa_covariance(0.3, 3)
    z = np.array([m.h(xi) for m, xi in zip(meas, x)]) + rng.normal(0, 0.5, (n, got_meas.dim))
    z[::3] += 8.0  # every third seed an outlier, for the gate
    gate = 9.0
    weights = merwe_weights(6, 0.8, 2.0, None)
    gx, gP, inn = unscented_correct(x, P, z, R, got_meas, gate, weights)
    assert 0 < inn.accepted.sum() < n  # both branches seen
    for i in range(n):
        f = UnscentedKalmanFilter(x[i], P[i], model, 0.8, 2.0, None)
        one = f.update(z[i], R, meas[i], gate)
        assert one.accepted == inn.accepted[i] and one.nis == inn.nis[i]
        assert np.array_equal(f.x, gx[i]) and np.array_equal(f.P, gP[i])
