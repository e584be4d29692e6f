"""The bulk path to a seed's batch arrays (host.batch.chunks.bulk_stream): bit for bit the
pipeline's records made a Stream, on seeds of every shipped scenario, or Unbatchable; each
irregularity it looks for, provoked on purpose, refused, and lab.batch's fallback then the
pipeline's records on the same chunks."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from navtwin.emulator.shipped import NAMES
from navtwin.host.batch import chunks
from navtwin.host.batch.chunks import bulk_stream
from navtwin.host.batch.estimator import BatchEstimator, Unbatchable, stream
from navtwin.lab import batch
from navtwin.lab.fleet import Follower
from navtwin.lab.run import lab_ports, scenario_of
from navtwin.protocols import nanoloc, sins, xbee
from navtwin.protocols.crcframe import encode

SEEDS = (1, 2, 3)
DURATION_S = 40.0  # past the aligner's window of 30 blocks
FILTERS = ("sins", "kf")
#: the scenarios whose runs the bulk path leaves to the pipeline: rssi-centroid's SINS stream
#: carries magnetometer frames
IRREGULAR = {"rssi-centroid"}


@functools.cache
def run_of(scenario: str, seed: int, duration: float = DURATION_S, direct: bool = False):
    sc = scenario_of(scenario)
    follower = None
    if direct:  # the host on the board's own line instead of the radio
        from navtwin.host import config as host_config
        from navtwin.host.replay import config_for
        follower = Follower(1, (1,), {"sins": "sins", "nanoloc": "nanoloc"},
                            host_config.load(config_for(sc.name)))
    return lab_ports(sc, seed, duration=duration, filters=FILTERS, follower=follower)


def pipeline_stream(kw, ports, bauds):
    """stream() of the pipeline's records, or the Unbatchable it raises."""
    cfg, recs = batch.records_of(kw, ports, bauds)
    try:
        return stream(recs, BatchEstimator(cfg, 0).takes(), frozenset(), cfg.imu_gap_s)
    except Unbatchable as e:
        return e


def bulk(kw, ports, bauds):
    return bulk_stream(ports, bauds, kw, kw["config"].estimator_config(kw["filters"]).imu_gap_s)


def assert_same(ref, got) -> None:
    for name in ref._fields:
        a, b = getattr(ref, name), getattr(got, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert np.array_equal(a, b, equal_nan=True), name


@pytest.mark.parametrize("scenario", NAMES)
def test_the_bulk_stream_is_the_pipelines_bit_for_bit(scenario):
    refused = 0
    for seed in SEEDS:
        kw, ports, bauds = run_of(scenario, seed)
        ref = pipeline_stream(kw, ports, bauds)
        try:
            got = bulk(kw, ports, bauds)
        except Unbatchable:
            refused += 1
            continue
        assert not isinstance(ref, Unbatchable), f"{scenario} seed {seed}: {ref}"
        assert_same(ref, got)
    assert refused == (len(SEEDS) if scenario in IRREGULAR else 0)


def test_the_direct_sins_line():
    kw, ports, bauds = run_of("office", 1, 10.0, direct=True)
    assert kw["inputs"] == ("sins", "nanoloc")
    assert_same(pipeline_stream(kw, ports, bauds), bulk(kw, ports, bauds))


@pytest.mark.parametrize("only", [("xbee",), ("nanoloc",)])
def test_one_input(only):
    """Samples alone; exchanges alone (nothing held beyond their chunk)."""
    kw, ports, bauds = run_of("office", 1, 10.0)
    kw, ports = {**kw, "inputs": only}, {p: ports[p] for p in only}
    assert_same(pipeline_stream(kw, ports, bauds), bulk(kw, ports, bauds))


def test_held_exchanges_replayed_in_turn_equal_the_vectorised_order():
    """Office's runs never time a hold out, so its order comes from the vectorised rule; the
    loop that replays the holds gives the same on them, and the convoy (whose coordinator
    carries three cars' samples) needs the loop and is checked above."""
    seen = {}
    original = chunks._time_order

    def spy(*args):
        seen["args"] = args
        return original(*args)

    chunks._time_order = spy
    try:
        kw, ports, bauds = run_of("office", 2)
        bulk(kw, ports, bauds)
    finally:
        chunks._time_order = original
    t_imu, pos_imu, t_r, pos_r, arrival, hold = seen["args"]
    fast = original(*seen["args"])
    first = np.searchsorted(pos_imu, pos_r, side="right")
    before = np.append(-np.inf, t_imu)[first]
    timeout = np.maximum(np.searchsorted(arrival - hold, arrival[pos_r]), pos_r)
    loop = chunks._held_in_turn(t_imu, pos_imu, t_r, pos_r, first, before, timeout, len(arrival))
    assert all(np.array_equal(a, b) for a, b in zip(fast, loop))


# -- runs broken on purpose --------------------------------------------------------------------

def _port(ports, name, frames, starts=None):
    """*ports* with port *name*'s chunks replaced by *frames* (and device times)."""
    _, sizes, start = ports[name]
    starts = start if starts is None else starts
    return {**ports, name: (b"".join(frames), np.array([len(f) for f in frames], np.int64),
                            np.asarray(starts, np.int64))}


def _frames(ports, name):
    data, sizes, start = ports[name]
    ends = np.cumsum(sizes)
    return [data[a:b] for a, b in zip(np.r_[0, ends[:-1]], ends)], start


def _packet(raw: bytes) -> bytes:
    """The frame data of an escaped API frame."""
    return xbee.unescape(raw[1:])[2:-1]


def _rx(ports):
    """Indices of the xbee chunks that are 0x90 packets."""
    frames, _ = _frames(ports, "xbee")
    return [k for k, f in enumerate(frames) if _packet(f)[0] == xbee.FrameType.RECEIVE_PACKET]


def _with_sins(ports, k, edit):
    """xbee chunk *k*'s SINS frame replaced by edit(frame): the packet rebuilt, checksum right."""
    frames, start = _frames(ports, "xbee")
    data = _packet(frames[k])
    frames[k] = xbee.wrap(data[:12] + edit(data[12:]), True)
    return _port(ports, "xbee", frames, start)


def _resample(frame: bytes, seq=None, words=None) -> bytes:
    f = sins.SinsFrame.parse(frame).body.value.payload
    return sins.build_sample(f.seq if seq is None else seq, f.words if words is None else words)


def _report(ports, k, **change):
    frames, start = _frames(ports, "nanoloc")
    f = nanoloc.NanolocFrame.parse(frames[k]).body.value.payload
    fields = {n: f[n] for n in ("seq", "t_us", "anchor", "tag", "status", "rssi", "tau")}
    frames[k] = nanoloc.build_report(**{**fields, **change})
    return _port(ports, "nanoloc", frames, start)


def xbee_two_frames_a_chunk(p):
    frames, start = _frames(p, "xbee")
    k = _rx(p)[50]
    return _port(p, "xbee", frames[:k] + [frames[k] + frames[k + 1]] + frames[k + 2:],
                 np.r_[start[:k + 1], start[k + 2:]])


def xbee_bad_escape(p):
    frames, start = _frames(p, "xbee")
    k = next(k for k in _rx(p) if b"\x7d" in frames[k])
    i = frames[k].index(b"\x7d")
    frames[k] = frames[k][:i + 1] + b"\x00" + frames[k][i + 2:]
    return _port(p, "xbee", frames, start)


def xbee_bad_length(p):
    frames, start = _frames(p, "xbee")
    k = _rx(p)[10]
    frames[k] = frames[k][:2] + bytes((frames[k][2] + 1,)) + frames[k][3:]
    return _port(p, "xbee", frames, start)


def xbee_bad_checksum(p):
    frames, start = _frames(p, "xbee")
    k = _rx(p)[10]
    frames[k] = frames[k][:-1] + bytes(((frames[k][-1] + 1) % 0x7D,))
    return _port(p, "xbee", frames, start)


def xbee_short_packet(p):
    frames, start = _frames(p, "xbee")
    frames[_rx(p)[10]] = xbee.wrap(bytes((xbee.FrameType.RECEIVE_PACKET, 0, 1, 2)), True)
    return _port(p, "xbee", frames, start)


def second_router(p):
    frames, start = _frames(p, "xbee")
    k = _rx(p)[10]
    data = bytearray(_packet(frames[k]))
    data[8] ^= 0x01  # the last byte of src64
    frames[k] = xbee.wrap(bytes(data), True)
    return _port(p, "xbee", frames, start)


def sins_byte_lost(p):
    return _with_sins(p, _rx(p)[10], lambda f: f[:10] + f[11:])


def sins_bad_crc(p):
    return _with_sins(p, _rx(p)[10], lambda f: f[:-1] + bytes((f[-1] ^ 1,)))


def sins_frame_in_tail(p):
    frames, start = _frames(p, "xbee")
    k = _rx(p)[-1]
    mag = _packet(frames[k])[:12] + sins.build_magnetometer(0, (1, 2, 3))
    return _port(p, "xbee", frames + [xbee.wrap(mag, True)], np.r_[start, start[-1] + 10**7])


def sins_stale(p):
    return _with_sins(p, _rx(p)[300], lambda f: _resample(
        f, words=[sins.SinsFrame.parse(f).body.value.payload.words[0] & 0x7FFF,
                  *sins.SinsFrame.parse(f).body.value.payload.words[1:]]))


def imu_gap(p):
    frames, start = _frames(p, "xbee")
    k = _rx(p)[500]
    return _port(p, "xbee", frames[:k] + frames[k + 60:], np.r_[start[:k], start[k + 60:]])


def imu_duplicate(p):
    k = _rx(p)[300]
    seq = sins.SinsFrame.parse(_packet(_frames(p, "xbee")[0][k - 1])[12:]).body.value.payload.seq
    return _with_sins(p, k, lambda f: _resample(f, seq=seq))


def imu_restart(p):
    """From sample 300 on the counter runs 5 s ahead of its arrival: a restart."""
    for k in _rx(p)[300:]:
        p = _with_sins(p, k, lambda f: _resample(
            f, seq=sins.SinsFrame.parse(f).body.value.payload.seq + 500))
    return p


def imu_min_step(p):
    """The first packet brings two samples: the second's time would equal the first's."""
    frames, start = _frames(p, "xbee")
    k, j = _rx(p)[:2]
    both = _packet(frames[k]) + _packet(frames[j])[12:]
    frames = frames[:k] + [xbee.wrap(both, True)] + frames[k + 1:j] + frames[j + 1:]
    return _port(p, "xbee", frames, np.r_[start[:j], start[j + 1:]])


def chunk_out_of_order(p):
    frames, start = _frames(p, "xbee")
    start = start.copy()
    k = _rx(p)[100]
    start[k] = start[k - 1] - 10**6
    return _port(p, "xbee", frames, start)


def report_split(p):
    frames, start = _frames(p, "nanoloc")
    return _port(p, "nanoloc", frames[:5] + [frames[5][:16], frames[5][16:]] + frames[6:],
                 np.r_[start[:6], start[5] + 10**6, start[6:]])


def report_bad_crc(p):
    frames, start = _frames(p, "nanoloc")
    frames[5] = frames[5][:-1] + bytes((frames[5][-1] ^ 1,))
    return _port(p, "nanoloc", frames, start)


def report_repeated(p):
    frames, start = _frames(p, "nanoloc")
    return _port(p, "nanoloc", frames[:6] + [frames[5]] + frames[6:],
                 np.r_[start[:6], start[5] + 10**6, start[6:]])


def report_same_time(p):
    frames, _ = _frames(p, "nanoloc")
    t_us = nanoloc.NanolocFrame.parse(frames[4]).body.value.payload.t_us
    return _report(p, 5, t_us=t_us)


def report_unknown_anchor(p):
    return _report(p, 5, anchor=99)


def report_between_anchors(p):
    return _report(p, 5, tag=2)


def report_wide(p):
    frames, start = _frames(p, "nanoloc")
    frames[5] = encode(nanoloc.SYNC, nanoloc.TYPE_WIDE_RANGING, bytes(30))
    return _port(p, "nanoloc", frames, start)


BROKEN = [
    (xbee_two_frames_a_chunk, "not one API frame"),
    (xbee_bad_escape, "bad escape"),
    (xbee_bad_length, "length"),
    (xbee_bad_checksum, "checksum"),
    (xbee_short_packet, "malformed 0x90"),
    (second_router, "several routers"),
    (sins_byte_lost, "back to back"),
    (sins_bad_crc, "SINS CRC"),
    (sins_frame_in_tail, "tail"),
    (sins_stale, "stale"),
    (imu_gap, "IMU gap"),
    (imu_duplicate, "duplicate"),
    (imu_restart, "restart"),
    (imu_min_step, r"\+1e-6"),
    (chunk_out_of_order, "out of their order"),
    (report_split, "not one report"),
    (report_bad_crc, "report's CRC"),
    (report_repeated, "duplicate"),
    (report_same_time, "duplicate"),
    (report_unknown_anchor, "unknown anchor"),
    (report_between_anchors, "between anchors"),
    (report_wide, "not one report"),
]


@pytest.mark.parametrize("broken, reason", BROKEN, ids=[b.__name__ for b, _ in BROKEN])
def test_an_irregular_run_is_refused(broken, reason):
    kw, ports, bauds = run_of("office", 1, 10.0)
    broken_ports = broken(ports)
    with pytest.raises(Unbatchable, match=reason):
        bulk(kw, broken_ports, bauds)


def test_a_clock_reset_is_refused():
    """A point more than step_s below the alignment's line resets the real aligner; the
    bulk path refuses it (through a counter, a jump that large is a restart first)."""
    device = np.arange(500) * 0.01
    arrival = device + 0.05
    arrival[300:] -= 1.5
    clock = chunks.imu_clock()
    for d, a in zip(device, arrival):
        clock.aligner.add(d, a)
    assert clock.aligner.resets == 1
    with pytest.raises(Unbatchable, match="clock reset"):
        chunks._aligned(chunks.imu_clock(), device, arrival)


def test_the_block_alignment_is_the_aligners():
    """Drift, jitter and late bursts over 60 blocks: the block-wise alignment gives the real
    aligner's host times, bit for bit."""
    rng = np.random.default_rng(5)
    device = np.arange(6000) * 0.01
    arrival = device * (1 + 6e-5) + 0.02 + rng.exponential(0.003, 6000)
    arrival[2000:2300] += 0.4  # the host stalled: late, not early
    assert np.array_equal(chunks._aligned(chunks.imu_clock(), device, arrival),
                          _hosts(device, arrival))


def _hosts(device, arrival):
    clock = chunks.imu_clock()
    out = []
    for d, a in zip(device, arrival):
        clock.aligner.add(d, a)
        out.append(clock.aligner.to_host(d))
    return np.array(out)


def test_api_mode_1_is_refused():
    kw, ports, bauds = run_of("office", 1, 10.0)
    with pytest.raises(Unbatchable, match="API mode 1"):
        bulk({**kw, "escaped": False}, ports, bauds)


@pytest.mark.parametrize("broken", [sins_bad_crc, imu_min_step, report_repeated, imu_gap])
def test_the_batch_engine_falls_back_to_the_pipeline_on_the_same_chunks(broken, monkeypatch):
    """lab.batch.run on a broken run: each seed's estimates those of its pipeline records,
    the bulk path refused (an IMU gap then ejects the seed: it runs per seed)."""
    kw, ports, bauds = run_of("office", 1, 10.0)
    broken_ports = broken(ports)
    monkeypatch.setattr(batch, "lab_ports_together", lambda *a, **k: [(kw, broken_ports, bauds)])
    out = batch.run("office", (1,), filters=FILTERS, duration=10.0)
    assert out.bulk == 0
    cfg, recs = batch.records_of(kw, broken_ports, bauds)
    ref = batch.columns(batch.per_seed(cfg, recs), FILTERS)
    for name in FILTERS:
        for c in batch.COLUMNS:
            assert np.allclose(ref[name][c], out.estimates[0][name][c], rtol=1e-9, atol=1e-9,
                               equal_nan=True), (name, c)


def test_office_takes_the_bulk_path():
    out = batch.run("office", (1, 2), filters=FILTERS, duration=10.0)
    assert out.bulk == 2 and out.ejected == {}
