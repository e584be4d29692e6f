"""Counter unwrapping and clock alignment against known device and host clocks."""
import math

import numpy as np
import pytest

from navtwin.host.clock import ClockAligner, DeviceClock, Unwrapper


def test_unwrap_counts_through_wraps_and_gaps():
    u = Unwrapper(16, 0.01)
    raw = [65533, 65534, 65535, 0, 1, 5, 6]  # a wrap, then frames 2..4 lost
    got = [u.unwrap(r, 0.01 * i)[0] for i, r in enumerate([65533, 65534, 65535, 0, 1, 5, 6])]
    # arrival times say one period each, but the counter is what counts
    assert got == [65533, 65534, 65535, 65536, 65537, 65541, 65542]
    assert raw[-1] + 65536 == got[-1]


def test_unwrap_uses_arrival_time_across_whole_wraps():
    # an outage of 700 s: the counter wrapped once (65536 x 10 ms = 655.36 s) plus 4464 samples
    u = Unwrapper(16, 0.01)
    u.unwrap(1000, 0.0)
    true_count = 1000 + 70_000
    value, step = u.unwrap(true_count % 65536, 700.0)
    assert value == true_count and step == 70_000


def test_unwrap_t_us_across_32_bit_wrap():
    u = Unwrapper(32, 1e-6)
    start = (1 << 32) - 10_000  # 10 ms before the wrap
    u.unwrap(start, 0.0)
    value, _ = u.unwrap((start + 25_000) % (1 << 32), 0.025)
    assert value == start + 25_000


def test_duplicates_and_small_steps_back_are_not_new():
    u = Unwrapper(16, 0.01, restart=100)
    u.unwrap(10, 0.0)
    u.unwrap(11, 0.01)
    assert u.unwrap(11, 0.02) == (11, 0)  # duplicate
    assert u.unwrap(9, 0.02) == (9, -2)  # older frame
    assert u.last == 11


def test_a_big_step_back_is_a_restart():
    u = Unwrapper(16, 0.01, restart=100)
    u.unwrap(5000, 0.0)
    u.unwrap(5001, 0.01)
    value, step = u.unwrap(0, 0.02)  # the board restarted its counter
    assert step is None and value == 0 and u.restarts == 1
    assert u.unwrap(1, 0.03) == (1, 1)


def test_a_count_far_ahead_of_the_elapsed_time_is_a_restart():
    u = Unwrapper(16, 0.01, restart=100)
    u.unwrap(100, 0.0)
    value, step = u.unwrap(5000, 0.01)  # 49 s of samples in 10 ms: a new counter
    assert step is None and value == 5000 and u.restarts == 1


def test_a_count_behind_the_elapsed_time_came_late_and_is_no_restart():
    u = Unwrapper(16, 0.01, restart=100)
    u.unwrap(5000, 0.0)
    # the host stalled 3 s: the next samples waited in the line and arrive together
    assert u.unwrap(5001, 3.0) == (5001, 1) and u.restarts == 0
    assert u.unwrap(5002, 3.0) == (5002, 1)


def test_a_host_stall_keeps_the_device_times_and_the_epoch():
    clock = DeviceClock(16, 0.01, strict=True)
    times = [clock.time(k, 0.005 + 0.01 * k) for k in range(300)]
    # 2 s without a read, then 2 s of samples at once, then live again
    times += [clock.time(k, 5.0) for k in range(300, 500)]
    times += [clock.time(k, 0.005 + 0.01 * k) for k in range(500, 600)]
    assert clock.counter.restarts == 0 and clock.aligner.resets == 0
    assert np.allclose(times, 0.005 + 0.01 * np.arange(600), atol=1e-3)


def test_a_counter_without_tick_restarts_on_any_step_back():
    u = Unwrapper(16, restart=0)
    u.unwrap(7, 0.0)
    assert u.unwrap(7, 0.1) == (7, 0)  # a duplicate
    assert u.unwrap(20, 0.2) == (20, 13)  # 12 lost, whatever the time
    assert u.unwrap(3, 0.3) == (3, None) and u.restarts == 1


def _arrivals(n, period, rate, offset, seed, dmin=0.004, jitter=0.002):
    """Device times k*period; arrival = offset + (1+rate)*device + dmin + Exp(jitter)."""
    rng = np.random.default_rng(seed)
    dev = np.arange(n) * period
    return dev, offset + (1 + rate) * dev + dmin + rng.exponential(jitter, n)


@pytest.mark.parametrize("rate_ppm", [-80.0, 0.0, 50.0])
def test_aligner_finds_rate_and_min_delay_envelope(rate_ppm):
    rate, offset, dmin = rate_ppm * 1e-6, 3.25, 0.004
    dev, arr = _arrivals(6000, 0.01, rate, offset, seed=1, dmin=dmin)
    a = ClockAligner()
    for d, t in zip(dev, arr):
        a.add(d, t)
    assert a.rate == pytest.approx(rate, abs=5e-6)
    # the host time of the last sample is its send time plus the minimum delay
    true = offset + (1 + rate) * dev[-1] + dmin
    assert abs(a.to_host(dev[-1]) - true) < 0.5e-3
    # and no arrival precedes the host time the envelope gives its sample (to within the
    # rate error across one block)
    assert all(a.to_host(d) <= t + 1e-5 for d, t in zip(dev[-3000:], arr[-3000:]))


def test_aligner_restarts_when_the_device_clock_steps():
    a = ClockAligner()
    dev, arr = _arrivals(500, 0.01, 0.0, 1.0, seed=2)
    for d, t in zip(dev, arr):
        a.add(d, t)
    # the device clock jumps 100 s ahead while arrivals go on
    for d, t in zip(dev[:200] + 105.0, arr[-1] + 0.01 + dev[:200]):
        a.add(d, t)
    assert a.resets == 1
    assert abs(a.to_host(105.0 + dev[199]) - (arr[-1] + 0.01 + dev[199])) < 0.01


def test_device_clock_rejects_duplicates_counts_losses_never_steps_back():
    c = DeviceClock(16, 0.01, strict=True)
    times = []
    seqs = [100, 101, 101, 102, 106, 107, 105, 108]
    for i, s in enumerate(seqs):
        times.append(c.time(s, 0.01 * i + 0.005))
    assert times[2] is None and times[6] is None  # the duplicate and the late copy
    assert c.duplicates == 2 and c.lost == 3  # 103..105 missing when 106 came
    kept = [t for t in times if t is not None]
    assert all(b >= a for a, b in zip(kept, kept[1:]))


def test_device_clock_gives_older_exchange_its_own_time():
    c = DeviceClock(32, 1e-6, strict=False)
    t1 = c.time(1_000_000, 0.010)
    t2 = c.time(1_030_000, 0.040)
    t_old = c.time(1_020_000, 0.041)  # reported late, happened before the previous one
    assert t_old < t2 and t_old == pytest.approx(t1 + 0.020, abs=1e-9)
    assert math.isfinite(t_old)


def test_a_host_stall_and_its_slow_catch_up_leave_the_alignment():
    # 3 s without a read from 8 s, then the backlog read at twice the line's pace: over 1 s
    # late for 4 s of reads, and whole blocks' minima seconds high
    dev, arr = _arrivals(2500, 0.01, 20e-6, 1.0, seed=3)
    late = np.maximum(arr, np.where(arr >= 9.0, 9.0 + 3.0 + (arr - 9.0) * 0.5, arr))
    clean, stalled = ClockAligner(), ClockAligner()
    worst = 0.0
    for d, a, b in zip(dev, arr, late):
        clean.add(d, a)
        stalled.add(d, b)
        worst = max(worst, abs(stalled.to_host(d) - clean.to_host(d)))
    assert stalled.resets == 0
    assert stalled.rate == pytest.approx(20e-6, abs=5e-6)
    assert worst < 1e-4  # s: the same host times, to the envelope's own noise
