"""The estimator's parts on their own (host/inertial.py, host/ranging.py, host/timebase.py):
the ranging part's TDMA cycles, corrections and products from synthetic exchanges, the
inertial part's alignment and gaps from a stationary synthetic IMU stream, the time base's
instants and lazy prediction."""
from __future__ import annotations

import math

import numpy as np
import pytest

from navtwin.host.settings import EstimatorConfig
from navtwin.host.inertial import Inertial
from navtwin.host.measurements import Exchange, Fix, FixRefused, ImuSample
from navtwin.host.ranging import Ranging
from navtwin.host.timebase import FilterTime
from navtwin.host.wsn import AnchorLayout

from ..helpers import GRAVITY, OFFICE_ANCHORS

AT = np.array([6.0, 3.0])


def ranging(**kw) -> Ranging:
    cfg = EstimatorConfig(anchors=OFFICE_ANCHORS, **kw)
    return Ranging(cfg, AnchorLayout(cfg.anchors, cfg.tag_height))


def exact(anchor: int, t: float, p=AT) -> Exchange:
    x, y, z = OFFICE_ANCHORS[anchor]
    return Exchange(t, anchor, math.dist((x, y, z), (*p, 0.0)))


# -- ranging ------------------------------------------------------------------------------

def test_a_cycle_closes_when_every_anchor_reported_or_one_reports_again_or_the_window_ends():
    r = ranging(cycle_s=0.1)
    assert [r.add(exact(a, 0.025 * a), 1.0) for a in (1, 2, 3)] == [[], [], []]
    (full,) = r.add(exact(4, 0.1), 1.0)  # the fourth anchor closes it
    assert full.anchors == [1, 2, 3, 4] and full.t == pytest.approx(0.0625)
    r.add(exact(1, 0.2), 1.0)
    (again,) = r.add(exact(1, 0.22), None)  # anchor 1 again: a new cycle; no distance
    assert again.anchors == [1]
    (late,) = r.add(exact(2, 0.35), 1.0)  # past the window after 0.22
    assert late.anchors == [1] and late.valid_anchors == [] and late.t == 0.22
    r.restart()  # no cycle spans a restart: anchor 2's open cycle is dropped
    assert [r.add(exact(a, 0.36 + 0.01 * a), 1.0) for a in (3, 1, 4)] == [[], [], []]
    (after,) = r.add(exact(2, 0.4), 1.0)
    assert after.anchors == [3, 1, 4, 2]


def test_exchanges_are_checked_and_corrected_and_counted_by_reason():
    r = ranging(range_bias_m={2: 0.3}, range_scale=1.1)
    assert not r.accept(Exchange(0.0, 9, 5.0)) and not r.accept(Exchange(math.nan, 1, 5.0))
    assert r.accept(Exchange(0.0, 2, 5.0))
    assert r.distance(Exchange(0.0, 2, 5.0)) == (5.0 - 0.3) / 1.1
    assert r.distance(Exchange(0.0, 1, 5.0)) == 5.0 / 1.1
    for rec in (Exchange(0.0, 1, None, status=0x4F), Exchange(0.0, 1, 5.0, status=0x01),
                Exchange(0.0, 1, 1e6), Exchange(0.0, 1, -1.0)):
        assert r.distance(rec) is None
    assert r.exchanges == 3
    assert r.rejections == {"unknown_anchor": 1, "range_implausible": 3, "outage": 1, "incomplete": 1}


def test_a_cycle_gives_its_fix_kept_with_the_previous_one_and_its_tdoa():
    r = ranging(reference_anchor=1, range_sigma_m=0.1)
    for k in range(3):
        for a in (1, 2, 3, 4):
            rec = exact(a, 0.1 * k + 0.025 * a)
            for cycle in r.add(rec, r.distance(rec)):
                fix = r.fix(cycle)
    assert isinstance(fix, Fix) and fix.p == pytest.approx(AT, abs=1e-6)
    assert [f.t for f in r.fixes] == pytest.approx([0.1625, 0.2625])  # the last two
    m = r.tdoa(cycle, fix, t=0.3)
    assert m.fix is fix and m.implausible == 0 and m.meas.anchors == (1, 2, 3, 4) and m.meas.dim == 3
    d = {a: exact(a, 0.0).distance for a in (1, 2, 3, 4)}
    assert m.z == pytest.approx([d[a] - d[1] for a in (2, 3, 4)])
    assert m.R == pytest.approx(0.01 * (np.eye(3) + np.ones((3, 3))))
    rng = r.range(exact(2, 0.25), 7.0, t=0.3)
    assert rng.z == [7.0] and rng.R == [[0.1**2]] and rng.meas.dim == 1


def test_a_cycle_of_two_ranges_is_refused_and_its_tdoa_has_too_few():
    r = ranging(cycle_s=0.1)
    r.add(exact(1, 0.0), 4.0)
    (cycle,) = r.add(exact(2, 0.02), 5.0) + r.add(exact(1, 0.05), 4.0)
    refused = r.fix(cycle)
    assert isinstance(refused, FixRefused) and r.fixes == []
    assert r.tdoa(cycle, None, t=0.05).meas is None


# -- inertial -----------------------------------------------------------------------------

def inertial(**kw) -> Inertial:
    return Inertial(EstimatorConfig(anchors=OFFICE_ANCHORS, **kw), need_sins=True)


def feed(part: Inertial, t: float, gyro=(0.0, 0.0, 0.0), accel=(0.0, 0.0, GRAVITY), **kw):
    if part.accept(ImuSample(t, gyro, accel, **kw)):
        return part.step(t)
    return "rejected"


def test_a_stationary_stream_aligns_then_the_strapdown_starts_at_the_origin():
    part = inertial(alignment_s=1.0, start=(2.0, 3.0))
    bias = (1e-3, -2e-3, 5e-4)
    roll, pitch = 0.02, -0.01  # the unit's tilt: gravity seen in the body axes
    accel = (-GRAVITY * math.sin(pitch), GRAVITY * math.sin(roll) * math.cos(pitch),
             GRAVITY * math.cos(roll) * math.cos(pitch))
    out = [feed(part, 0.01 * k, bias, accel) for k in range(150)]
    assert out[:100] == [None] * 100 and part.sins is not None  # aligning: no acceleration
    assert part.t_aligned == 0.99 and part.aligned.samples == 100  # the alignment's last sample
    assert part.aligned.roll == pytest.approx(roll, abs=1e-9)
    assert part.aligned.pitch == pytest.approx(pitch, abs=1e-9)
    assert part.aligned.gyro_bias == pytest.approx(bias, abs=1e-4)  # the earth rate is in it
    assert np.hypot(*out[-1]) < 1e-3 and part.sins.p[:2] == pytest.approx((2.0, 3.0), abs=1e-4)
    assert part.motion(1.49, None).kind == "stationary"
    m = part.motion(1.49, out[-1])
    assert m.kind == "accel" and m.R[0, 0] > 1.0  # accel_sigma_m_s2 = 1 and the tilt growth
    assert part.stats()["samples"] == 100


def test_samples_are_checked_and_gaps_bridged_or_not_and_counted():
    part = inertial(alignment_s=0.5, imu_gap_s=0.5)
    for k in range(60):
        feed(part, 0.01 * k)
    assert feed(part, 0.3) == "rejected"  # out of order
    assert feed(part, 0.7, nd_ok=False) == "rejected"
    assert feed(part, math.inf) == "rejected"
    assert feed(part, 0.7, gyro=(6.0, 0.0, 0.0)) is not None  # over 300 deg/s: counted, taken
    assert not part.gap(0.71) and part.counts["gaps_bridged"] == 0  # no sample lost
    assert not part.gap(0.9) and part.gaps() == {"bridged": 1, "reinit": 0}
    assert part.gap(1.5) and part.gaps() == {"bridged": 1, "reinit": 1} and part.t_imu == 1.5
    assert part.rejections == {"imu_out_of_order": 1, "imu_stale": 1, "imu_implausible": 1}
    assert part.counts["samples"] == 64 and part.counts["overrange"] == 1


def test_an_imu_restart_realigns_at_the_mean_of_the_fixes_since():
    part = inertial(alignment_s=0.5, start=(6.0, 1.8))
    for k in range(60):
        feed(part, 0.01 * k)
    part.restart(0.6, uptime_s=0.0)
    assert part.sins is None and part.origin == (6.0, 1.8)
    for t, p in ((0.5, (9.0, 9.0)), (0.65, (3.0, 4.0)), (0.75, (5.0, 2.0))):  # the first is older
        part.fix(Fix(t, np.array(p), np.eye(2), (1, 2, 3), 0.0))
    assert part.origin == (4.0, 3.0)
    out = [feed(part, 0.6 + 0.01 * k) for k in range(1, 60)]
    assert out[0] is None and out[-1] is not None  # aligned again, from the restart
    assert part.sins.p[:2] == pytest.approx((4.0, 3.0), abs=1e-3)


# -- the time base ------------------------------------------------------------------------

def test_the_output_instants_are_k_periods_from_the_first_at_or_after_the_first_measurement():
    time = FilterTime(output_period_s=0.1, extrapolated_after_s=0.5)
    time.start(0.237)
    assert time.next_out == 3 * 0.1
    for _ in range(4):
        time.next_instant()
    assert time.next_out == 7 * 0.1  # k times the period, not a running sum of it


def test_the_filter_time_is_the_latest_measurement_and_staleness():
    time = FilterTime(output_period_s=0.1, extrapolated_after_s=0.5)
    time.start(1.0)
    for t in (1.1, 1.05, 1.3):  # a late measurement leaves the filter time
        time.advance(t)
    assert time.t == 1.3
    assert not time.stale(1.5, None) and time.stale(1.6, None)  # from the first measurement
    assert not time.stale(2.0, 1.6) and time.stale(2.2, 1.6)