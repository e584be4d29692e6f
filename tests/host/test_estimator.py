"""The fusion core on synthetic lab data: outputs, accuracy against truth, bad input, outages."""
from __future__ import annotations

import dataclasses
import math
from collections import defaultdict

import numpy as np
import pytest

from navtwin.host.estimator import Estimate, Estimator
from navtwin.host.measurements import Exchange, ImuSample, Restart
from navtwin.host.tracks import DEFAULT

from ..helpers import GRAVITY, OFFICE_ANCHORS, office_config, tight
from .navsynth import ellipse, exchanges, noisy_imu, perfect_imu, record

FILTER_NAMES = DEFAULT

ALIGN = 3.0


def office_truth(t):
    return ellipse(np.atleast_1d(t), omega=0.1, t_start=ALIGN + 1.0, ramp=2.0)


def synth_events(seconds, seed=1, *, noise=True, sigma=0.15, drop=lambda t, a: False, range_bias=0.0,
                 gyro_bias=(0.002, -0.003, 0.004), roll=0.0, pitch=0.0):
    """Time-ordered calls [(t, "imu", args) | (t, "range", args)] for the office ellipse."""
    rng = np.random.default_rng(seed)
    t = np.round(np.arange(0.0, seconds, 0.01), 9)
    tr = office_truth(t)
    gyro, accel = perfect_imu(tr, roll=roll, pitch=pitch)
    if noise:
        gyro, accel = noisy_imu(gyro, accel, rng, gyro_bias=gyro_bias)
    else:
        gyro = gyro + np.asarray(gyro_bias)
    ev = [(tk, 0, "imu", (tk, gyro[k], accel[k])) for k, tk in enumerate(t)]
    for tk, a, d in exchanges(office_truth, OFFICE_ANCHORS, duration=seconds, sigma=sigma if noise else 0.0,
                              rng=rng, t0=0.005):
        if drop(tk, a):
            ev.append((tk, 1, "range", (tk, a, None, -90, 0x40)))
        else:
            ev.append((tk, 1, "range", (tk, a, d + range_bias, -60, 0x0F)))
    ev.sort(key=lambda e: e[:2])
    return [(e[2], e[3]) for e in ev]


def run(cfg=None, calls=None, **kw):
    est = Estimator(cfg or office_config(alignment_s=ALIGN, range_sigma_m=0.15))
    out = []
    for kind, args in calls if calls is not None else synth_events(**{"seconds": 30.0, **kw}):
        out += est.feed(record(kind, args))
    return est, out


def errors(out, t_from=0.0, t_to=math.inf):
    by = defaultdict(list)
    for e in out:
        if t_from <= e.t <= t_to:
            p = office_truth(e.t).p[0]
            by[e.filter].append(math.hypot(e.x - p[0], e.y - p[1]))
    return {k: np.array(v) for k, v in by.items()}


@pytest.fixture(scope="module")
def default_run():
    return run()


def test_config_errors_name_the_field_and_the_fix():
    with pytest.raises(ValueError, match=r"filters: unknown \['pf'\]; use some of sins,wsn,kf,ekf,ukf"):
        office_config(filters=("kf", "pf"))
    with pytest.raises(ValueError, match=r"\[filters.ekf\] tight must be one of 'toa', 'tdoa' \(got 'rss'\); "
                                         "use one of 'toa', 'tdoa'"):
        office_config(settings=tight("rss"))
    with pytest.raises(ValueError, match=r"output_period_s must be in \[0.001, 60\] \(got 0"):
        office_config(output_period_s=0)
    with pytest.raises(ValueError, match="anchors: 2 given"):
        office_config(anchors={1: (0, 0), 2: (1, 0)})
    with pytest.raises(ValueError, match=r"extrapolated_after_s must be in \(0, 3600\] \(got 0"):
        office_config(extrapolated_after_s=0.0)
    with pytest.raises(ValueError, match=r"reinit_sigma must be a list of 2 numbers \(got \[1\]\)"):
        office_config(reinit_sigma=(1.0,))
    with pytest.raises(ValueError, match="device 'gps': use one of imu, anchors"):
        Estimator(office_config()).feed(Restart(1.0, "gps"))


def test_one_estimate_per_filter_per_period_in_config_order(default_run):
    est, out = default_run
    assert all(isinstance(e, Estimate) for e in out)
    by_t = defaultdict(list)
    for e in out:
        by_t[e.t].append(e.filter)
    times = sorted(by_t)
    assert [round(t * 10) for t in times] == list(range(0, 300))  # 0.0 .. 29.9 s, every 0.1 s
    assert [e.t for e in out] == sorted(e.t for e in out)
    for t in times[3:]:  # wsn starts with its second fix
        assert by_t[t] == list(FILTER_NAMES)
    assert est.stats()["estimates"] == {n: len([e for e in out if e.filter == n]) for n in FILTER_NAMES}
    assert all(len(e.cov) == 16 for e in out)
    cov = np.array(out[-1].cov).reshape(4, 4)
    np.testing.assert_allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_same_calls_same_estimates(default_run):
    _, out = default_run
    _, again = run()
    assert again == out


def test_fusion_beats_both_pure_tracks_and_sins_drifts(default_run):
    est, out = default_run
    err = errors(out, t_from=ALIGN)
    for name in ("kf", "ekf", "ukf"):
        assert err[name].mean() < err["wsn"].mean(), name
        assert err[name].mean() < err["sins"].mean(), name
        assert err[name].max() < 0.5, name
    assert err["wsn"].max() < 1.0  # bounded, however long it runs
    sins = err["sins"]
    assert sins[-1] > 5 * sins[len(sins) // 4]  # drift grows with time
    assert est.stats()["alignment"]["samples"] == ALIGN / 0.01


def test_stationary_exact_data_stays_at_the_start():
    """Perfect IMU (with a gyro bias the alignment removes) and exact ranges, parked."""
    est, out = run(calls=synth_events(ALIGN + 1.0, noise=False))
    assert {e.filter for e in out} == set(FILTER_NAMES)
    for e in out:
        assert math.hypot(e.x - 6.0, e.y - 1.8) < 1e-3, e
        assert math.hypot(e.vx, e.vy) < 1e-3, e
        assert e.yaw is None if e.filter == "wsn" else abs(e.yaw) < 1e-6


def test_anchor_outage_is_counted_and_bridged():
    """Anchor 2 silent for 5 s (timeout reports): 3 anchors still give TDOA, and the
    fusion filters stay on track."""
    out_window = lambda t, a: a == 2 and 10.0 <= t < 15.0
    est, out = run(drop=out_window)
    assert est.stats()["input_rejections"]["outage"] == 50
    err = errors(out, 10.0, 15.0)
    for name in ("kf", "ekf", "ukf"):
        assert err[name].max() < 0.6, name
    # three ranges, two differences: an exact TDOA fix without redundancy, noisier but there
    assert err["wsn"].max() < 2.0 and est.stats()["updates"]["wsn"]["fix"] == 300


def test_total_wsn_outage_coasts_on_the_sins_and_recovers():
    gone = lambda t, a: 12.0 <= t < 16.0
    est, out = run(drop=gone)
    err = errors(out)
    during = errors(out, 12.0, 16.0)
    after = errors(out, 19.0, 30.0)
    for name in ("kf", "ekf", "ukf"):
        assert during[name].max() < 2.0, name  # 4 s on the SINS acceleration alone
        assert after[name].max() < 0.5, name
    assert err["wsn"].size > 0
    assert est.stats()["input_rejections"]["outage"] == 160


def test_bad_input_is_counted_not_fatal():
    est = Estimator(office_config(alignment_s=1.0))
    g, f = np.zeros(3), np.array([0.0, 0.0, GRAVITY])
    est.feed(ImuSample(0.0, g, f))
    est.feed(ImuSample(0.01, g, f, nd_ok=False))
    est.feed(ImuSample(0.01, [np.nan, 0, 0], f))
    est.feed(ImuSample(0.0, g, f))  # not after the previous sample
    est.feed(Exchange(0.02, 9, 5.0, -60, 0x0F))
    est.feed(Exchange(0.03, 1, -1.0, -60, 0x0F))
    est.feed(Exchange(0.04, 1, 1e6, -60, 0x0F))
    est.feed(Exchange(0.05, 2, None, -90, 0x40))
    est.feed(Exchange(0.06, 3, 4.0, -60, 0x80))
    est.feed(ImuSample(0.02, g, f))
    s = est.stats()
    assert s["input_rejections"] == {"imu_implausible": 1, "imu_out_of_order": 1, "imu_stale": 1,
                                     "incomplete": 1, "outage": 1, "range_implausible": 2, "unknown_anchor": 1}
    assert s["imu_samples"] == 5 and s["exchanges"] == 5


def test_late_measurements_use_their_lag_or_are_refused():
    cfg = office_config(alignment_s=ALIGN, settings=tight("toa"), filters=("ekf", "ukf"))
    calls = synth_events(6.0, noise=False)
    imus = [c for c in calls if c[0] == "imu"]
    ranges = [c for c in calls if c[0] == "range"]
    est = Estimator(cfg)
    for kind, args in imus:  # all IMU first: every range arrives after the filters' time
        est.feed(ImuSample(*args))
    for kind, args in ranges[-5:]:  # lag < 0.5 s
        est.feed(Exchange(*args))
    est.feed(Exchange(*ranges[0][1]))  # almost 6 s old
    s = est.stats()
    assert s["updates"]["ekf"]["range"] == 5 and s["updates"]["ukf"]["range"] == 5
    assert s["rejections"]["ekf"] == {"late": 1} and s["rejections"]["ukf"] == {"late": 1}


def test_an_outlier_range_is_gated_in_the_tight_filters():
    cfg = office_config(alignment_s=ALIGN, settings=tight("toa"), range_sigma_m=0.15)
    calls = synth_events(20.0, noise=True)
    k = next(i for i, (kind, a) in enumerate(calls) if kind == "range" and a[0] > 15.0)
    t, a, d, rssi, status = calls[k][1]
    calls[k] = ("range", (t, a, d + 8.0, rssi, status))
    est, out = run(cfg, calls)
    s = est.stats()
    assert s["rejections"]["ekf"]["gate"] >= 1 and s["rejections"]["ukf"]["gate"] >= 1
    err = errors(out, 15.0)
    assert err["ekf"].max() < 0.5 and err["ukf"].max() < 0.5


def test_calibrated_range_bias_is_removed():
    biased = dict(range_bias=0.5, seconds=12.0)
    cfg = dict(alignment_s=ALIGN, range_sigma_m=0.15, wsn_method="toa", filters=("wsn",))
    _, raw = run(office_config(**cfg), **biased)
    _, fixed = run(office_config(**cfg, range_bias_m={1: 0.5, 2: 0.5, 3: 0.5, 4: 0.5}), **biased)
    assert errors(fixed)["wsn"].mean() < 0.5 * errors(raw)["wsn"].mean()


def test_alignment_of_a_tilted_unit_is_reported():
    est, _ = run(seconds=5.0, roll=0.03, pitch=-0.02, noise=False)
    a = est.stats()["alignment"]
    assert a["roll_rad"] == pytest.approx(0.03, abs=1e-9)
    assert a["pitch_rad"] == pytest.approx(-0.02, abs=1e-9)
    np.testing.assert_allclose(a["gyro_bias_rad_s"], [0.002, -0.003, 0.004], atol=1e-12)
    assert a["specific_force_m_s2"] == pytest.approx(GRAVITY, rel=1e-6)


@pytest.mark.parametrize("filters", [("wsn",), ("kf",), ("ukf", "sins")])
def test_a_subset_of_filters(filters):
    est, out = run(office_config(alignment_s=ALIGN, filters=filters, range_sigma_m=0.15), seconds=6.0)
    assert {e.filter for e in out} == set(filters)
    assert (est.stats()["alignment"] is None) == (filters == ("wsn",))


def test_fusion_yaw_follows_the_turning_vehicle(default_run):
    """Heading error within 4 sigma of the ARW: its random walk plus the bias the alignment
    leaves (ARW / sqrt(T_align)) integrated over the time since."""
    _, out = default_run
    arw = math.radians(4.2) / 60.0
    for e in out:
        if e.filter in ("kf", "ukf", "sins") and e.t > ALIGN:
            yaw = office_truth(e.t).yaw[0]
            T = e.t - ALIGN
            sigma = arw * math.sqrt(T * T / ALIGN + T)
            assert abs(math.remainder(e.yaw - yaw, math.tau)) < max(4 * sigma, 1e-3), e
        if e.filter == "wsn":
            assert e.yaw is None


@pytest.mark.parametrize("ranges,wsn", [("toa", "toa"), ("tdoa", "toa"), ("toa", "tdoa")])
def test_other_measurement_choices_also_track(ranges, wsn):
    est, out = run(office_config(alignment_s=ALIGN, range_sigma_m=0.15, settings=tight(ranges),
                                 wsn_method=wsn, filters=("wsn", "kf", "ekf", "ukf")), seconds=20.0)
    err = errors(out, ALIGN)
    for name in ("kf", "ekf", "ukf"):
        assert err[name].mean() < err["wsn"].mean() and err[name].max() < 0.5, name


def restarted_run(first_s, gap_s, second_s, cfg=None, **kw):
    """The lab restarted gap_s after a run of first_s (host time goes on): the vehicle back at
    its start, at rest for the alignment, then the same trip; the devices' restarts are
    told as the pipeline tells them, before their first new measurement. Returns the
    estimator, the estimates and the restart time."""
    t1 = first_s + gap_s
    second = [(kind, (args[0] + t1, *args[1:])) for kind, args in synth_events(second_s, seed=2, **kw)]
    calls = [*synth_events(first_s, seed=1, **kw), ("restart", (second[0][1][0], "imu")),
             ("restart", (second[0][1][0], "anchors")), *second]
    est, out = run(cfg, calls)
    return est, out, t1


def restarted_errors(out, t1, t_from, t_to=math.inf):
    """Errors of the estimates in [t_from, t_to] against the restarted run's truth."""
    return errors([dataclasses.replace(e, t=e.t - t1) for e in out if t_from <= e.t <= t_to])


def test_a_device_restart_reinitialises_every_track_and_realigns_the_sins():
    est, out, t1 = restarted_run(15.0, 6.0, 15.0)
    s = est.stats()
    assert s["reinit"] == {n: {"restart": 1} for n in FILTER_NAMES}  # both devices: one each
    assert s["reinit_pending"] == [] and s["alignment"]["samples"] == ALIGN * 100
    err = restarted_errors(out, t1, t1 + 0.5)
    for name in ("kf", "ekf", "ukf"):
        assert err[name].max() < 0.5, name
    assert err["wsn"].max() < 1.0
    # realigned at the start: the same few decimetres as after the first alignment
    first = errors([e for e in out if e.t < 15.0], ALIGN, 15.0)
    assert err["sins"].max() < 2 * first["sins"].max() + 0.1


@pytest.mark.parametrize("gap_s", [0.2, 3.0])
def test_estimates_of_a_restarted_track_before_its_first_fix_are_extrapolated(gap_s):
    est, out, t1 = restarted_run(10.0, gap_s, 5.0)
    gap = [e for e in out if 10.0 + 0.5 < e.t < t1]
    assert all(e.extrapolated for e in gap if e.filter != "sins")
    # the new run's first fix comes 0.08 s after the restart: until then the tracks wait
    waiting = [e for e in out if t1 - 1e-9 <= e.t < t1 + 0.08 and e.filter in ("kf", "ekf", "ukf")]
    assert len(waiting) == 3 and all(e.extrapolated for e in waiting)
    assert all(not e.extrapolated for e in out if e.t >= t1 + 0.5)


def test_a_track_gated_out_for_too_long_starts_again_at_the_next_fix():
    # from 12 s on, every range says the vehicle is 3.2 m off where the IMU says it went
    # (picked up and put down): the filters' own position updates are gated out
    calls = synth_events(25.0)
    moved = lambda p: p + np.array([2.5, 2.0])
    for i, (kind, args) in enumerate(calls):
        if kind == "range" and args[0] >= 12.0 and args[2] is not None:
            t, a, _, rssi, status = args
            d = math.dist(moved(office_truth(t).p[0]), OFFICE_ANCHORS[a][:2])
            calls[i] = ("range", (t, a, d, rssi, status))
    est, out = run(calls=calls)
    s = est.stats()
    for name in ("kf", "ekf", "ukf"):
        assert s["reinit"][name] == {"gated": 1}, name
        assert "gate_reopened" not in s["rejections"][name]
    late = [e for e in out if e.t >= 15.0 and e.filter in ("kf", "ekf", "ukf")]
    for e in late:
        assert math.dist((e.x, e.y), moved(office_truth(e.t).p[0])) < 0.5, e


def test_a_total_outage_marks_the_estimates_it_bridges_as_extrapolated():
    gone = lambda t, a: 12.0 <= t < 16.0
    _, out = run(drop=gone)
    after = office_config().extrapolated_after_s
    for e in out:
        if e.filter == "sins":
            assert not e.extrapolated  # the IMU never stopped
        elif 12.0 + after + 0.1 <= e.t < 16.0:
            assert e.extrapolated, e
        elif e.t < 12.0 + after or e.t >= 16.0 + 0.2:
            assert not e.extrapolated, e


def test_extrapolated_after_s_is_a_setting():
    gone = lambda t, a: 12.0 <= t < 16.0
    _, out = run(office_config(alignment_s=ALIGN, range_sigma_m=0.15, extrapolated_after_s=2.0,
                                 filters=("ekf",)), drop=gone)
    marked = [e.t for e in out if e.extrapolated]
    assert marked and 14.0 <= min(marked) < 14.2 and max(marked) < 16.2
