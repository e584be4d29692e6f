"""The batch twins of 001's error-state tracks (host.batch.tracks: lc, tc, fatci): each seed's
estimates equal the in-memory run's on seeds of every shipped scenario, and the strapdown
and process-noise pieces they add equal the per-seed ones."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.shipped import NAMES
from navtwin.host.batch.estimator import BatchEstimator, stream
from navtwin.host.batch.strapdown import BatchStrapdown
from navtwin.host.estimator import Estimator
from navtwin.host.filters.errorstate import process_noise, process_noises
from navtwin.lab import batch
from navtwin.lab.run import run_in_memory

from .test_batch import DURATION_S, SEEDS, assert_equal, strapdowns

TWINS = ("lc", "tc", "fatci")
FILTERS = ("sins", "wsn", "kf", *TWINS)
#: tc and fatci hold one NLOS state per anchor: outage-bridging's 1402 anchors make their P
#: 1409 x 1409, stepped at 100 Hz, minutes per seed alone (per seed as in the batch)
ANCHOR_FIELDS = {"outage-bridging"}


@pytest.mark.parametrize("scenario", NAMES)
def test_each_seed_equals_the_in_memory_run(scenario):
    sc = load_scenario(scenario)
    filters = FILTERS[:4] if scenario in ANCHOR_FIELDS else FILTERS
    out = batch.run(sc, SEEDS, filters=filters, duration=DURATION_S)
    assert out.batched == filters
    for seed, got in zip(SEEDS, out.estimates):
        est, _ = run_in_memory(sc, seed, filters=filters, duration=DURATION_S)
        assert_equal(batch.columns(est, filters), got, f"{scenario} seed {seed}")


def test_office_runs_the_error_state_twins_as_a_batch():
    """Office is the common path: no seed leaves the batch, and every twin is aided (its own
    yaw, corrected by the updates, differs from the estimator's strapdown's)."""
    out = batch.run("office", SEEDS, filters=FILTERS, duration=DURATION_S)
    assert out.ejected == {}
    for e in out.estimates:
        for name in TWINS:
            assert len(e[name]["t"]) > 100
            assert not e[name]["extrapolated"][-1]
            assert not np.array_equal(e[name]["yaw"], e["sins"]["yaw"])


def test_the_strapdown_twin_corrects_copies_and_places_as_the_strapdown():
    rng = np.random.default_rng(11)
    n = 6
    site = dict(latitude_deg=48.1, altitude_m=500.0, x_azimuth_deg=120.0)
    alone, source = strapdowns(rng, n, site)
    twin = BatchStrapdown(n, **site)
    twin.take(np.arange(n), source)
    for step in range(300):
        idx = np.flatnonzero(rng.random(n) < 0.7)
        dt = rng.uniform(0.005, 0.02, len(idx))
        gyro, accel = rng.normal(0, 0.3, (len(idx), 3)), rng.normal(0, 2, (len(idx), 3))
        twin.step(idx, dt, gyro, accel)
        for k, i in enumerate(idx):
            alone[i].step(float(dt[k]), tuple(gyro[k]), tuple(accel[k]))
            np.testing.assert_allclose(twin.f_n[i], alone[i].f_n, rtol=0, atol=1e-13)
        dp, dv = rng.normal(0, 0.1, (len(idx), 2)), rng.normal(0, 0.05, (len(idx), 2))
        # small and tiny attitude errors: quat_from_rotvec's series below 1e-4 rad too
        da = rng.normal(0, 1e-3 if step % 2 else 1e-6, (len(idx), 3))
        twin.correct(idx, dp, dv, da)
        for k, i in enumerate(idx):
            alone[i].correct(dp[k], dv[k], da[k])
    idx = np.array([1, 4])
    p, v = rng.normal(size=(2, 2)), rng.normal(size=(2, 2))
    twin.place(idx, p, v)
    for k, i in enumerate(idx):
        alone[i].place(p[k], v[k])
    copy = BatchStrapdown(n, **site)
    copy.take(np.arange(n), twin)  # a copy steps on as the original does
    for i in range(n):
        for got in (twin, copy):
            np.testing.assert_allclose(got.p[i], alone[i].p, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(got.v[i], alone[i].v, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(got.q[i], alone[i].q, rtol=0, atol=1e-13)


def test_the_process_noise_of_many_intervals_is_each_intervals():
    """process_noises takes dt^2 and dt^3 as Python's float powers: numpy's power rounds a few
    percent of the IMU's jittered periods otherwise, so every entry must be equal, not close."""
    rng = np.random.default_rng(3)
    dt = np.concatenate([0.01 + rng.normal(0, 1e-5, 3000), rng.uniform(0, 1, 300)])
    for extra in (0, 1, 4):
        noise = (1.2e-8, 2.8e-6, 2.5e-3, extra)
        many = process_noises(dt, *noise)
        process_noise.cache_clear()
        for k, d in enumerate(dt.tolist()):
            assert np.array_equal(many[k], process_noise(d, *noise)), (extra, d)


@pytest.mark.parametrize("name", TWINS)
def test_a_track_gated_out_starts_again_at_the_next_fix_as_the_per_seed_one(name):
    """Every update gated out for gate_reopen_s: the track is off (its estimates
    extrapolated) until the next fix, at which it starts again; the twin does the same."""
    cfg, recs = batch.records("office", 1, filters=(name,), duration=DURATION_S)
    # the vehicle 20 m from where the track starts, sure of it to 5 cm: every update is
    # gated out until the track starts again at a fix
    cfg = replace(cfg, start=(cfg.start[0] + 20.0, cfg.start[1]), p0_sigma=(0.05, *cfg.p0_sigma[1:]))
    alone = Estimator(cfg)
    want = batch.columns([e for r in recs for e in alone.feed(r)], cfg.filters)
    assert alone.stats()["reinit"][name] == {"gated": 1}
    engine = BatchEstimator(cfg, 2)
    stream_ = stream(recs, engine.takes(), frozenset(), cfg.imu_gap_s)
    got = engine.run([stream_, stream_])
    assert engine.ejected == {}
    for g in got:
        assert_equal(want, g, name)
    off = want[name]["extrapolated"]
    assert off.any() and not off[-1]  # off while it waited, aided again after
