"""The pipeline: decoded bytes -> measurements in time order, deterministically.

The estimator here is the recording stand-in, so the tests see exactly what the pipeline
gives the filters and when.
"""
import math

import numpy as np
import pytest

from navtwin.host import config as host_config
from navtwin.host.pipeline import Pipeline
from navtwin.protocols import adis16350, nanoloc, sins, xbee
from navtwin.protocols.stream import XBeeDecoder

from ..helpers import OFFICE
from .fake_estimator import RecordingEstimator
from .synthetic import ROUTER64, synthetic_chunks



def run(chunks, **kw):
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, **kw)
    out = []
    for port, data, t_ns in chunks:
        out += pipe.feed(port, data, t_ns)
    out += pipe.finish()
    return pipe, est, out


def test_synthetic_lab_gives_every_sample_and_exchange_in_time_order():
    chunks = list(synthetic_chunks(OFFICE, 10.0, seed=3))
    pipe, est, out = run(chunks)
    imu = [c for c in est.calls if c[0] == "imu"]
    ranges = [c for c in est.calls if c[0] == "range"]
    assert len(imu) == 1000 and len(ranges) == 400
    times = [c[1] for c in est.calls]
    assert all(b >= a for a, b in zip(times, times[1:]))
    # the board's 30 ppm fast crystal: 10 ms nominal samples are 10.0003 ms apart on the host
    span = imu[-1][1] - imu[0][1]
    assert span / 999 == pytest.approx(0.01 * (1 + 30e-6), abs=2e-6)
    assert pipe.vehicles[0].imu_clock.aligner.rate == pytest.approx(30e-6, abs=10e-6)
    # level and standing: about 1 local g on z, nothing on the gyros beyond noise
    az = np.mean([c[3][2] for c in imu])
    assert az == pytest.approx(OFFICE.local_gravity, abs=0.01)
    assert np.abs([c[2] for c in imu]).max() < math.radians(0.5)
    # every 50th exchange timed out; the others give the distances to the start point
    timeouts = [c for c in ranges if c[3] is None]
    assert len(timeouts) == 8 and all(c[5] == nanoloc.STATUS_TIMEOUT for c in timeouts)
    for _, _, anchor, d, _, _ in ranges:
        if d is not None:
            true = math.dist(OFFICE.vehicles[0].start, OFFICE.anchors[anchor][:2])
            assert abs(d - true) < 0.3  # 5 cm noise, 6 sigma
    assert pipe.counts["reports_lost"] == 0 and pipe.vehicles[0].imu_clock.lost == 0
    assert sum(pipe.errors["xbee"].values()) == sum(pipe.errors["nanoloc"].values()) == 0
    assert len(out) > 0


def test_measurement_times_follow_the_device_clocks_not_the_arrival_jitter():
    chunks = list(synthetic_chunks(OFFICE, 20.0, seed=4))
    _, est, _ = run(chunks)
    imu = np.array([c[1] for c in est.calls if c[0] == "imu"])
    steps = np.diff(imu[-1000:])  # after the envelope settled
    # radio jitter is ~1 ms exponential; the aligned times are regular to a few microseconds
    assert np.abs(steps - 0.01 * (1 + 30e-6)).max() < 50e-6
    # host time = send time + minimum delay: the first sample was sent at 0.05 s and needs at
    # least 2.6 ms (board UART) + 3 ms (radio) + 3.5 ms (coordinator UART)
    k = np.arange(imu.size)
    sent = 0.05 + k * 0.01 * (1 + 30e-6)
    lag = imu[-1000:] - sent[-1000:]
    assert lag.min() > 0.0085 and lag.max() < 0.0105


def test_same_chunks_same_calls_and_estimates():
    chunks = list(synthetic_chunks(OFFICE, 5.0, seed=5))
    _, est1, out1 = run(chunks)
    _, est2, out2 = run(chunks)
    assert est1.calls == est2.calls and out1 == out2


def test_byte_at_a_time_delivery_gives_the_same_measurements():
    chunks = list(synthetic_chunks(OFFICE, 3.0, seed=6))
    split = [(p, data[i:i + 1], t + i) for p, data, t in chunks for i in range(len(data))]
    _, whole, _ = run(chunks)
    _, bytewise, _ = run(split)
    assert len(whole.calls) == len(bytewise.calls)
    for a, b in zip(whole.calls, bytewise.calls):
        assert a[0] == b[0] and a[2:] == b[2:]
        assert a[1] == pytest.approx(b[1], abs=1e-5)  # arrival differs by the bytes' ns


def _sins_chunk(seq, t_s, words=None):
    words = words or adis16350.sample_to_words(gyro_dps=(0, 0, 0), accel_g=(0, 0, 1))
    return "sins", sins.build_sample(seq, words), round(t_s * 1e9)


def _report(seq, t_us, t_s, anchor=1, status=nanoloc.STATUS_COMPLETE, tag=0x10):
    # the taus of the wire-format test vector (anchor 1, true 5.000 m, decodes to 4.99994 m)
    tau = (0x05F6634C, 0x05F5E100, 0x05F6634C, 0x05F5E100)
    if status != nanoloc.STATUS_COMPLETE:
        tau = (0, 0, 0, 0)
    data = nanoloc.build_report(seq=seq, t_us=t_us, anchor=anchor, tag=tag, status=status,
                                rssi=-70, tau=tau)
    return "nanoloc", data, round(t_s * 1e9)


def test_a_range_ahead_of_the_imu_waits_for_the_sample_that_passes_it():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("sins", "nanoloc"))
    # SINS samples arrive 3 ms after their 10 ms ticks; anchor time 0 = host 0
    for k in range(5):
        pipe.feed(*_sins_chunk(k, 0.003 + 0.01 * k))
    pipe.feed(*_report(0, 0, 0.0))  # establishes the anchor clock
    n_before = len(est.calls)
    # an exchange at anchor time 50 ms arrives before the sample of 50 ms does
    pipe.feed(*_report(1, 45_000, 0.0455))
    assert len(est.calls) == n_before  # held
    pipe.feed(*_sins_chunk(5, 0.053))
    kinds = [c[0] for c in est.calls[n_before:]]
    assert kinds == ["range", "imu"]
    t_range, t_imu = est.calls[n_before][1], est.calls[n_before + 1][1]
    assert t_range < t_imu


def test_a_held_range_is_released_by_arrival_time_when_the_imu_stalls():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("sins", "nanoloc"))
    for k in range(3):
        pipe.feed(*_sins_chunk(k, 0.003 + 0.01 * k))
    pipe.feed(*_report(0, 40_000, 0.0405))  # ahead of the last sample (20 ms): held
    assert est.calls[-1][0] == "imu"
    pipe.feed(*_report(1, 50_000, 0.0505))  # arrival 50.5 ms < 40.5 + 20 ms: still held
    assert est.calls[-1][0] == "imu"
    pipe.feed(*_report(2, 65_000, 0.065))  # arrival >= 60.5 ms: only the first is released
    assert [c[0] for c in est.calls[-2:]] == ["imu", "range"]
    assert pipe.stats()["held"] == 2
    pipe.finish()
    assert pipe.stats()["held"] == 0
    assert [c[0] for c in est.calls[-3:]] == ["range"] * 3


def test_late_ranges_go_to_the_estimator_at_once_with_their_own_time():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("sins", "nanoloc"))
    pipe.feed(*_report(0, 1_000_000, 0.0005))  # anchor clock: t_us 1 s = host 0.5 ms
    for k in range(50):
        pipe.feed(*_sins_chunk(k, 0.003 + 0.01 * k))
    t_filter = pipe.vehicles[0].t
    pipe.feed(*_report(1, 1_000_000 + 480_000, 0.495))  # happened at 0.4805 s, before T
    assert est.calls[-1][0] == "range"
    assert est.calls[-1][1] == pytest.approx(0.4805, abs=1e-9) and t_filter > 0.4805
    pipe.feed(*_report(2, 1_000_000 + 350_000, 0.496))  # a report 0.14 s late
    assert est.calls[-1][1] == pytest.approx(0.3505, abs=1e-9)
    assert pipe.counts["ranges_late"] == 2 and pipe.vehicles[0].t == t_filter
    assert pipe.max_late_s == pytest.approx(t_filter - 0.3505, abs=1e-9)


def test_duplicate_sins_frames_are_dropped_and_gaps_counted():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("sins",))
    for k, seq in enumerate([7, 8, 8, 9, 13, 14]):
        pipe.feed(*_sins_chunk(seq, 0.003 + 0.01 * k))
    assert sum(1 for c in est.calls if c[0] == "imu") == 5
    assert pipe.vehicles[0].imu_clock.duplicates == 1 and pipe.vehicles[0].imu_clock.lost == 3


def test_corrupt_bytes_are_counted_and_the_next_frames_used():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("sins",))
    words = adis16350.sample_to_words(gyro_dps=(0, 0, 0), accel_g=(0, 0, 1))
    bad = bytearray(sins.build_sample(1, words))
    bad[10] ^= 0xFF
    pipe.feed("sins", b"\x00\x01" + bytes(bad), 1_000_000)
    pipe.feed("sins", sins.build_sample(2, words), 11_000_000)
    assert pipe.errors["sins"]["bad_crc"] == 1 and pipe.errors["sins"]["garbage"] >= 1
    assert sum(1 for c in est.calls if c[0] == "imu") == 1


def test_ranges_of_other_tags_and_unknown_anchors_are_not_used():
    est = RecordingEstimator()
    d = OFFICE.to_dict()
    cfg = host_config.from_dict({**d, "vehicle": {**d["vehicle"], "tag": 0x10}})
    pipe = Pipeline(cfg, make_estimator=lambda _: est, inputs=("nanoloc",))
    pipe.feed(*_report(0, 0, 0.001, anchor=1))
    pipe.feed(*_report(1, 25_000, 0.026, anchor=9))
    other = nanoloc.build_report(seq=2, t_us=50_000, anchor=2, tag=0x11, status=0x0F, rssi=-1,
                                 tau=(1, 0, 1, 0))
    pipe.feed("nanoloc", other, 51_000_000)
    assert [c[2] for c in est.calls] == [1]
    assert pipe.counts["reports_unknown_anchor"] == 1 and pipe.counts["reports_other_tag"] == 1


@pytest.mark.parametrize("tag", [None, 0x10])
def test_an_exchange_between_two_anchors_goes_to_every_vehicle_as_theirs(tag):
    """A report whose tag field holds an anchor's id: the anchors ranged each other (emulator's
    anchor_exchange_every_cycles). It is the network's, never a vehicle's range, even with no
    tag configured (where every tag's exchanges are the one vehicle's)."""
    est = RecordingEstimator()
    d = OFFICE.to_dict()
    cfg = OFFICE if tag is None else host_config.from_dict({**d, "vehicle": {**d["vehicle"], "tag": tag}})
    pipe = Pipeline(cfg, make_estimator=lambda _: est, inputs=("nanoloc",))
    pipe.feed(*_report(0, 0, 0.001, anchor=1, tag=2))
    pipe.feed(*_report(1, 25_000, 0.026, anchor=2))
    pipe.feed(*_report(2, 50_000, 0.051, anchor=3, tag=1, status=nanoloc.STATUS_TIMEOUT))
    pipe.finish()
    assert [c[:4] for c in est.calls if c[0] != "range"] == [("anchors", pytest.approx(0.0, abs=0.01), 1, 2),
                                                             ("anchors", pytest.approx(0.05, abs=0.01), 3, 1)]
    anchors = [c for c in est.calls if c[0] == "anchors"]
    assert anchors[0][4] == pytest.approx(4.99994, abs=5e-6) and anchors[1][4] is None
    assert [c[2] for c in est.calls if c[0] == "range"] == [2]
    assert pipe.counts["anchor_exchanges"] == 2 and pipe.counts["ranges"] == 1
    assert pipe.counts["reports_other_tag"] == 0 and pipe.counts["timeouts"] == 0


def test_distance_is_the_four_timestamp_formula():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("nanoloc",))
    pipe.feed(*_report(0, 0, 0.001))
    assert est.calls[0][3] == pytest.approx(4.99994, abs=5e-6)  # wire-formats.md section 3


def test_db_query_every_five_seconds_of_arrival_and_its_answer():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("xbee",))
    modem = xbee.build(xbee.FrameType.MODEM_STATUS, True, status=6)
    pipe.feed("xbee", modem, 1_000)
    tx = pipe.take_tx()
    pipe.feed("xbee", modem, 4_000_000_000)
    assert pipe.take_tx() == b""
    pipe.feed("xbee", modem, 5_000_001_000)
    tx2 = pipe.take_tx()
    frames = XBeeDecoder(escaped=True).decode(tx + tx2)
    assert [(f.type, f.fields["frame_id"], f.fields["command"]) for f in frames] == \
        [(0x08, 1, b"DB"), (0x08, 2, b"AP"), (0x08, 3, b"DB"), (0x08, 4, b"AP")]
    # python-xbee builds the same bytes for the same requests
    from xbee.frame import APIFrame
    assert tx == APIFrame(b"\x08\x01DB", escaped=True).output() + \
        APIFrame(b"\x08\x02AP", escaped=True).output()
    answer = xbee.build(xbee.FrameType.AT_RESPONSE, True, frame_id=1, command=b"DB", status=0,
                        value=b"\x30")
    pipe.feed("xbee", answer, 5_100_000_000)
    assert pipe.link_dbm == -0x30 and pipe.modem_status == 6


def test_only_the_vehicle_router_feeds_the_imu():
    est = RecordingEstimator()
    pipe = Pipeline(OFFICE, make_estimator=lambda _: est, inputs=("xbee",))
    words = adis16350.sample_to_words(gyro_dps=(0, 0, 0), accel_g=(0, 0, 1))
    for k, src in enumerate([ROUTER64, ROUTER64 + 1, ROUTER64]):
        frame = xbee.build(0x90, True, src64=src, src16=1, options=1,
                           data=sins.build_sample(k, words))
        pipe.feed("xbee", frame, 10_000_000 * (k + 1))
    assert sum(1 for c in est.calls if c[0] == "imu") == 2
    assert pipe.counts["imu_other_router"] == 1


def test_devices_that_restart_start_new_clock_epochs_and_lose_nothing():
    first = list(synthetic_chunks(OFFICE, 3.0, seed=7))
    # the lab is power-cycled: counters start again from other values 1 s later
    second = [(p, d, t + 4_000_000_000) for p, d, t in
              synthetic_chunks(OFFICE, 3.0, seed=8, seq0=0, t_us0=123_456)]
    pipe, est, _ = run(first + second)
    assert sum(c[0] == "imu" for c in est.calls) == 600
    assert sum(c[0] == "range" for c in est.calls) == 240
    assert pipe.vehicles[0].imu_clock.counter.restarts == 1 and pipe.range_clock.counter.restarts == 1
    assert pipe.counts["reports_duplicate"] == 0 and pipe.vehicles[0].imu_clock.duplicates == 0
    imu = [c[1] for c in est.calls if c[0] == "imu"]
    assert all(b > a for a, b in zip(imu, imu[1:]))
    # the second epoch's times are its own arrival times again (to the link delay)
    assert imu[300] == pytest.approx(4.05 + 0.0085, abs=0.003)
    # the estimator is told, once per device, just before the first measurement of its epoch
    restarts = [i for i, c in enumerate(est.calls) if c[0] == "restart"]
    assert sorted(est.calls[i][2] for i in restarts) == ["anchors", "imu"]
    for i in restarts:
        kind = "imu" if est.calls[i][2] == "imu" else "range"
        nxt = next(c for c in est.calls[i + 1:] if c[0] == kind)
        assert sum(c[0] == kind for c in est.calls[:i]) == (300 if kind == "imu" else 120)
        assert nxt[1] == pytest.approx(est.calls[i][1], abs=0.05)
    times = [c[1] for c in est.calls]
    assert all(b >= a for a, b in zip(times, times[1:]))


def test_api_mode_1_and_the_direct_line_give_the_same_samples():
    api2 = [c for c in synthetic_chunks(OFFICE, 2.0, seed=9) if c[0] == "xbee"]
    api1 = [c for c in synthetic_chunks(OFFICE, 2.0, seed=9, escaped=False) if c[0] == "xbee"]
    direct = [c for c in synthetic_chunks(OFFICE, 2.0, seed=9, via="sins") if c[0] == "sins"]
    samples = []
    for chunks_, kw in ((api2, {}), (api1, {"escaped": False}), (direct, {})):
        _, est, _ = run(chunks_, **kw)
        samples.append([c[2:] for c in est.calls])
    assert len(samples[0]) == 200 and samples[0] == samples[1] == samples[2]


def test_a_sample_on_both_the_radio_and_the_direct_line_counts_once():
    radio = [c for c in synthetic_chunks(OFFICE, 2.0, seed=10) if c[0] == "xbee"]
    direct = [c for c in synthetic_chunks(OFFICE, 2.0, seed=10, via="sins") if c[0] == "sins"]
    both = sorted(radio + [(p, d, t + 1) for p, d, t in direct], key=lambda c: c[2])
    pipe, est, _ = run(both, inputs=("xbee", "sins"))
    assert sum(c[0] == "imu" for c in est.calls) == 200
    assert pipe.vehicles[0].imu_clock.duplicates == 200


# -- the coordinator's API mode ------------------------------------------------------------------

def _ap_answer(mode, fid=9, escaped=True):
    return xbee.build(xbee.FrameType.AT_RESPONSE, escaped, frame_id=fid, command=b"AP", status=0,
                      value=b"" if mode is None else bytes((mode,)))


def test_at_queries_read_the_same_in_api_mode_1_and_2():
    pipe = Pipeline(OFFICE, make_estimator=lambda _: RecordingEstimator(), inputs=("xbee",))
    tx = b""
    for k in range(300):  # wraps the frame ID
        pipe.feed("xbee", b"", k * 5_000_000_000)
        tx += pipe.take_tx()
    plain = XBeeDecoder(escaped=False).decode(tx)
    assert [(f.fields["frame_id"], f.raw) for f in XBeeDecoder(escaped=True).decode(tx)] == \
        [(f.fields["frame_id"], f.raw) for f in plain]
    assert len(plain) == 600 and {f.fields["command"] for f in plain} == {b"DB", b"AP"}
    ids = {f.fields["frame_id"] for f in plain}
    assert 0 not in ids and {0x11, 0x13, 0x7D, 0x7E}.isdisjoint(ids) and len(ids) > 200


@pytest.mark.parametrize("escaped,other", [(True, 1), (False, 2)])
def test_an_ap_answer_that_differs_from_the_host_mode_is_said_once_and_counted(escaped, other):
    pipe = Pipeline(OFFICE, make_estimator=lambda _: RecordingEstimator(), inputs=("xbee",), escaped=escaped)
    host = 2 if escaped else 1
    pipe.feed("xbee", _ap_answer(host, escaped=escaped), 1)
    assert pipe.take_events() == [] and pipe.coordinator_api == host  # as expected: silent
    for k in range(3):
        pipe.feed("xbee", _ap_answer(other, escaped=escaped), 10 + k)
    (event,) = pipe.take_events()
    assert (event["event"], event["coordinator_api"], event["host_api"]) == \
        ("api_mode_mismatch", other, host)
    fix = "--api1" if other == 1 else "without --api1"
    assert f"switched to API {other}" in event["message"] and fix in event["message"]
    assert f"send ATAP{host}" in event["message"]
    assert pipe.counts["api_mode_mismatch"] == 3 and pipe.stats()["coordinator_api"] == other
    pipe.feed("xbee", _ap_answer(host, escaped=escaped), 20)
    assert [e["event"] for e in pipe.take_events()] == ["api_mode_ok"]


def test_another_clients_ap_set_answer_makes_the_host_ask_at_once():
    pipe = Pipeline(OFFICE, make_estimator=lambda _: RecordingEstimator(), inputs=("xbee",))
    pipe.feed("xbee", b"", 1)
    pipe.take_tx()
    pipe.feed("xbee", _ap_answer(None), 1_000_000_000)  # "AP set OK", no value
    asked = XBeeDecoder(escaped=True).decode(pipe.take_tx())
    assert [f.fields["command"] for f in asked] == [b"DB", b"AP"]
