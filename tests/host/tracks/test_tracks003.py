"""Paper 003's tracks (docs/filters.md, "003's tracks"): centroid and wcl take the RSSI of
each cycle's exchanges and aid the geodetic SINS (host.tracks.geodetic); on synthetic data with RSSI shadowing both bound
the SINS's drift, and the weighted centroid's error is no larger than the centroid's."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import t as t_dist

from navtwin.host import rssi
from navtwin.host.estimator import Estimator
from navtwin.host.measurements import AnchorExchange, Exchange, ImuSample
from navtwin.host.settings import EstimatorConfig
from navtwin.host.tracks import BUILT_IN, get
from navtwin.host.tracks.centroid import CentroidSettings, CentroidTrack, WclTrack
from navtwin.host.tracks.geodetic import GeodeticTrack, GeoSinsTrack

from ...helpers import GRAVITY, LATITUDE_DEG, OFFICE_ANCHORS
from ..navsynth import drive_after_rest, exchanges

ALIGN_S, DURATION_S = 5.0, 60.0
LAMBDA, N, SHADOWING_DB = -45.0, 2.0, 2.0
TRACKS = ("sins", "centroid", "wcl")


def run(seed: int, tracks=TRACKS, shadowing_db=SHADOWING_DB, settings=None, anchor_rounds=0):
    """One run on an ellipse in the office: a perfect IMU at rest, then white noise and an
    accelerometer bias that make the pure SINS drift; each exchange's RSSI by 003 eq. 2 with
    shadowing N(0, shadowing_db^2), rounded to the report's whole dBm. Returns each track's
    horizontal errors (m) once a second while moving. *anchor_rounds*: each ordered pair of
    anchors ranges itself that many times during the rest (AnchorExchange, the same model)."""
    rng = np.random.default_rng(seed)
    traj, t, tr, gyro, accel = drive_after_rest(rng, align_s=ALIGN_S, duration_s=DURATION_S,
                                                accel_bias=(0.02, -0.015, 0.0))
    ex = exchanges(traj, OFFICE_ANCHORS, duration=DURATION_S, sigma=0.0, rng=rng, t0=0.003)
    settings = settings or CentroidSettings(rssi_1m_dbm=LAMBDA, path_loss_exponent=N)
    cfg = EstimatorConfig(anchors=OFFICE_ANCHORS, latitude_deg=LATITUDE_DEG, local_gravity=GRAVITY,
                          start=tuple(tr.p[0]), heading_deg=0.0, alignment_s=ALIGN_S,
                          wsn_method="toa", filters=tracks,
                          settings={"centroid": settings, "wcl": settings})
    est = Estimator(cfg)
    records = [(ti, 0, ImuSample(ti, g, f)) for ti, g, f in zip(t, gyro, accel)]
    for te, a, d in ex:
        level = np.rint(rssi.rssi(d, LAMBDA, N) + rng.normal(0.0, shadowing_db))
        records.append((te, 1, Exchange(te, a, 30.0, int(level))))  # the TOF distance unused
    ids = sorted(OFFICE_ANCHORS)
    pairs = [(a, b) for a in ids for b in ids if a != b]
    for k in range(anchor_rounds * len(pairs)):
        a, b = pairs[k % len(pairs)]
        d = np.linalg.norm(np.subtract(OFFICE_ANCHORS[a], OFFICE_ANCHORS[b]))
        level = np.rint(rssi.rssi(d, LAMBDA, N) + rng.normal(0.0, shadowing_db))
        te = 0.0005 + k * ALIGN_S / 2 / (anchor_rounds * len(pairs))
        records.append((te, 1, AnchorExchange(te, a, b, 30.0, int(level))))
    out = []
    for _, _, rec in sorted(records, key=lambda r: r[:2]):
        out += est.feed(rec)
    errors = {name: [] for name in tracks}
    for e in out:
        if e.t < ALIGN_S + 1.0 or round(e.t * 10) % 10:
            continue
        k = int(round(e.t * 100))
        errors[e.filter].append(np.hypot(e.x - tr.p[k, 0], e.y - tr.p[k, 1]))
    return {name: np.array(v) for name, v in errors.items()}, est


def test_registered_after_001s_on_the_geodetic_filter():
    assert BUILT_IN[8:11] == ("centroid", "wcl", "geosins")
    assert get("centroid") is CentroidTrack and get("wcl") is WclTrack and get("geosins") is GeoSinsTrack
    assert issubclass(CentroidTrack, GeodeticTrack) and issubclass(WclTrack, CentroidTrack)


def test_exact_rssi_fixes_hold_the_track_on_the_truth():
    errors, est = run(0, ("centroid", "wcl"), shadowing_db=0.0)
    for name in ("centroid", "wcl"):
        track = next(tr for tr in est.tracks if tr.name == name)
        assert track.updates["fix"] > 400  # about one per cycle, 10 Hz
        # the whole-dBm rounding alone: a fraction of a metre
        assert errors[name].mean() < 0.6, (name, errors[name].mean())


@pytest.mark.slow
def test_both_bound_the_sins_drift_and_wcl_is_no_worse_than_centroid():
    means = {name: [] for name in TRACKS}
    for seed in range(6):
        errors, _ = run(seed)
        for name in TRACKS:
            means[name].append(errors[name].mean())
            if name != "sins":
                assert errors[name][-10:].max() < 4.0, (seed, name)  # bounded to the end
        assert errors["sins"][-1] > 15.0, seed  # the pure SINS runs off
    m = {name: np.array(v) for name, v in means.items()}
    diff = m["wcl"] - m["centroid"]  # paired by seed: the upper end of its 95 % interval
    assert diff.mean() + t_dist.ppf(0.975, len(diff) - 1) * diff.std(ddof=1) / np.sqrt(len(diff)) < 0.0, m


def test_adaptive_path_loss_learns_the_channel_from_the_anchors_readings():
    """003 eqs. 3-8: a host configured with the wrong channel (RSSI(1 m) -40 dBm, n = 3 against
    -45, 2) fixes far off; with adaptive_path_loss and the anchors' readings of one another
    (50 rounds during the rest) it fits the channel: each anchor's (lambda_i, n_i) near the
    truth, the fixes as good as the right fixed model's; with no readings it falls back on
    the configured model and counts every cycle."""
    wrong = dict(rssi_1m_dbm=-40.0, path_loss_exponent=3.0)
    right, _ = run(1, ("wcl",))
    fixed, _ = run(1, ("wcl",), settings=CentroidSettings(**wrong))
    adaptive, est = run(1, ("wcl",), settings=CentroidSettings(**wrong, adaptive_path_loss=True),
                        anchor_rounds=50)
    track = est.tracks[-1]
    lam_i, n_i = track._fitted
    assert np.allclose(lam_i, LAMBDA, atol=3.0) and np.allclose(n_i, N, atol=0.3), (lam_i, n_i)
    assert fixed["wcl"].mean() > 1.5 * right["wcl"].mean()  # 1.8-2.4x over seeds 0-2
    assert adaptive["wcl"].mean() < 1.25 * right["wcl"].mean(), (adaptive["wcl"].mean(), right["wcl"].mean())
    assert track.rejections["path_loss_unfitted"] == 0
    unfitted, est = run(1, ("wcl",), settings=CentroidSettings(**wrong, adaptive_path_loss=True))
    assert np.array_equal(unfitted["wcl"], fixed["wcl"])
    assert est.tracks[-1].rejections["path_loss_unfitted"] > 500


def test_an_adaptive_fit_outside_the_models_range_falls_back_on_the_configured_model():
    """Readings that do not fall with distance (every pair heard at -70 dBm) fit n = 0, every
    distance infinite: the cycle takes the configured model and counts it."""
    _, est = run(1, ("wcl",), settings=CentroidSettings(adaptive_path_loss=True))
    track = est.tracks[-1]
    ids = sorted(OFFICE_ANCHORS)
    for a in ids:
        for b in ids:
            if a != b:
                track.anchor_exchange(AnchorExchange(100.0, a, b, 5.0, -70))
    before = track.rejections["path_loss_implausible"]
    assert track.path_loss(ids, np.array([-60.0, -62.0, -65.0, -70.0])) == (LAMBDA, N)
    assert abs(track._fitted[1]).max() < 1e-9 and track.rejections["path_loss_implausible"] == before + 1
