"""The batch engine (lab.batch, host.batch.estimator): each seed's estimates equal the
in-memory run's, on seeds of every shipped scenario, whichever tracks it batches."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from navtwin.emulator.shipped import NAMES
from navtwin.host.batch.estimator import BatchEstimator, Unbatchable, stream
from navtwin.host.batch.strapdown import BatchStrapdown
from navtwin.host.batch.tracks import batchable
from navtwin.host.sins import Strapdown
from navtwin.lab import batch
from navtwin.lab.run import run_in_memory
from navtwin.lab.sweep import default_filters
from navtwin.emulator.scenario import load_scenario

SEEDS = (1, 2)
DURATION_S = 15.0


def assert_equal(ref: dict, got: dict, what: str, tol: float = 1e-9) -> None:
    """Every column of every track equal to *tol* (relative above 1)."""
    assert list(got) == list(ref), what
    for name, cols in ref.items():
        assert len(got[name]["t"]) == len(cols["t"]), f"{what} {name}: estimate count"
        for c in batch.COLUMNS:
            a, b = np.asarray(cols[c], float), np.asarray(got[name][c], float)
            assert np.array_equal(np.isnan(a), np.isnan(b)), f"{what} {name}.{c}"
            ok = np.isnan(a) | (np.abs(a - b) <= tol * np.maximum(1.0, np.abs(a)))
            assert ok.all(), f"{what} {name}.{c}: max difference {np.nanmax(np.abs(a - b))}"


@pytest.mark.parametrize("scenario", NAMES)
def test_each_seed_equals_the_in_memory_run(scenario):
    sc = load_scenario(scenario)
    filters = tuple(dict.fromkeys((*default_filters(sc), "sins", "wsn", "kf")))
    out = batch.run(sc, SEEDS, filters=filters, duration=DURATION_S)
    assert out.batched == batchable(filters) and out.batched
    for seed, got in zip(SEEDS, out.estimates):
        est, _ = run_in_memory(sc, seed, filters=filters, duration=DURATION_S)
        assert_equal(batch.columns(est, filters), got, f"{scenario} seed {seed}")


def test_a_tracks_estimates_do_not_depend_on_its_companions():
    """Each fusion track predicts to its own time (host/tracks/fusion.py), so kf alone gives
    what kf beside ekf and ukf gives, bit for bit: what lets the engine run tracks apart."""
    cfg, recs = batch.records("office", 3, filters=("kf", "ekf", "ukf"), duration=DURATION_S)
    together = batch.columns(batch.per_seed(cfg, recs), cfg.filters)
    for name in cfg.filters:
        alone = batch.columns(batch.per_seed(replace(cfg, filters=(name,)), recs), (name,))
        for c in batch.COLUMNS:
            assert np.array_equal(alone[name][c], together[name][c], equal_nan=True), (name, c)


def test_office_runs_as_a_batch():
    """Office is the common path: no seed leaves the batch (else the batch proves little)."""
    out = batch.run("office", (1, 2, 3), filters=("sins", "wsn", "kf"), duration=DURATION_S)
    assert out.ejected == {}
    assert all(len(e["kf"]["t"]) > 100 for e in out.estimates)


def test_a_gap_is_bridged_in_the_batch_and_a_longer_one_leaves_it():
    cfg, recs = batch.records("office", 1, filters=("sins", "kf"), duration=DURATION_S)
    imu = [k for k, r in enumerate(recs) if type(r).__name__ == "ImuSample"]
    takes = BatchEstimator(cfg, 0).takes()
    long_gap = recs[:imu[900]] + recs[imu[960]:]  # 0.6 s lost: the tracks would start again
    with pytest.raises(Unbatchable, match="gap"):
        stream(long_gap, takes, frozenset(), cfg.imu_gap_s)
    short = recs[:imu[900]] + recs[imu[905]:]  # 50 ms lost: bridged, the next step spans it
    engine = BatchEstimator(cfg, 2)
    got = engine.run([stream(r, takes, frozenset(), cfg.imu_gap_s) for r in (recs, short)])
    assert engine.ejected == {}
    for r, g in zip((recs, short), got):
        assert_equal(batch.columns(batch.per_seed(cfg, r), cfg.filters), g, "office seed 1")


def strapdowns(rng, n: int, site: dict):
    """n strapdowns at random starts, attitudes and gyro biases: each alone, and a twin of
    them all begun there."""
    q0 = rng.normal(size=(n, 4))
    q0 /= np.linalg.norm(q0, axis=1)[:, None]
    start, bias = rng.normal(size=(n, 2)), rng.normal(0, 1e-3, (n, 3))
    alone = [Strapdown(position=start[i], q=q0[i], gyro_bias=bias[i], local_gravity=9.81, **site)
             for i in range(n)]
    twin = BatchStrapdown(n, **site)
    twin.begin(np.arange(n), start, q0, bias)
    return alone, twin


def test_the_strapdown_twin_steps_each_seed_as_the_strapdown_alone():
    rng = np.random.default_rng(5)
    n, steps = 7, 400
    alone, twin = strapdowns(rng, n, dict(latitude_deg=52.2, altitude_m=70.0, x_azimuth_deg=60.0))
    for _ in range(steps):
        idx = np.flatnonzero(rng.random(n) < 0.8)  # some seeds sit a step out
        dt = rng.uniform(0.0, 0.02, len(idx))
        gyro, accel = rng.normal(0, 0.3, (len(idx), 3)), rng.normal(0, 2, (len(idx), 3))
        acc = twin.step(idx, dt, gyro, accel)
        for k, i in enumerate(idx):
            expect = alone[i].step(float(dt[k]), tuple(gyro[k]), tuple(accel[k]))
            np.testing.assert_allclose(acc[k], expect[:2], rtol=0, atol=1e-12)
    for i in range(n):
        np.testing.assert_allclose(twin.p[i], alone[i].p, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(twin.v[i], alone[i].v, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(twin.q[i], alone[i].q, rtol=0, atol=1e-13)
        assert twin.yaw(np.array([i]))[0] == pytest.approx(alone[i].yaw, abs=1e-13)
