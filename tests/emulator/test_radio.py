"""The XBee router's packetisation (RO, NP) and the RF link (latency, loss, retries)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from navtwin.protocols.serial import char_ns
from navtwin.emulator.radio import RF_OVERHEAD_BYTES, Link, Router
from navtwin.protocols.ieee802154 import ACK_NS, BYTE_NS
from navtwin.emulator.rng import stream
from navtwin.emulator.faults import LinkLoss
from navtwin.emulator.scenario import load_scenario

from .world_helpers import port_bytes, run, variant

CHAR = char_ns(115200)  # 86.8 us


def frame_stream(n_frames: int, period_ns: int = 10_000_000, size: int = 30):
    data = bytes(range(256)) * (n_frames * size // 256 + 1)
    data = data[:n_frames * size]
    starts = np.arange(n_frames, dtype=np.int64) * period_ns + 1_000_000
    times = (starts[:, None] + np.rint(np.arange(1, size + 1) * CHAR).astype(np.int64)).ravel()
    return data, times, int(starts[-1] + period_ns + round(CHAR))


def test_each_sins_frame_is_one_packet_ro_after_its_last_byte():
    data, times, nxt = frame_stream(5)
    p = Router(84, 3, CHAR).packetise(data, times, nxt)
    assert p.payloads == [data[i * 30:(i + 1) * 30] for i in range(5)]
    assert np.array_equal(p.ready_ns, times[29::30] + round(3 * CHAR))


def test_np_limit_and_long_ro_make_full_packets():
    """RO 255 (22 ms) is longer than the gap between frames: the stream flows on and the
    router sends a packet each time NP bytes are buffered, at the arrival of the NP-th."""
    data, times, nxt = frame_stream(10)
    p = Router(84, 255, CHAR).packetise(data, times, nxt)
    assert [len(x) for x in p.payloads] == [84, 84, 84]  # 300 bytes: 48 still buffered
    assert np.array_equal(p.ready_ns, times[[83, 167, 251]])
    flushed = Router(84, 255, CHAR)
    q = flushed.packetise(data, times, None)
    assert b"".join(q.payloads) == data and len(q.payloads[-1]) == 48
    assert q.ready_ns[-1] == times[-1] + round(255 * CHAR)


def test_ro_zero_sends_every_byte_alone():
    data, times, nxt = frame_stream(1)
    p = Router(84, 0, CHAR).packetise(data, times, nxt)
    assert p.payloads == [data[i:i + 1] for i in range(30)]


@pytest.mark.parametrize("ro, np_bytes", [(3, 84), (255, 84), (255, 20), (0, 84), (150, 7)])
def test_packetising_in_pieces_equals_packetising_at_once(ro, np_bytes):
    data, times, nxt = frame_stream(40)
    whole = Router(np_bytes, ro, CHAR).packetise(data, times, None)
    pieces = Router(np_bytes, ro, CHAR)
    got, ready = [], []
    cuts = [0, 7, 11, 12, 25, 40]
    for a, b in zip(cuts, cuts[1:]):
        last = b == 40
        p = pieces.packetise(data[a * 30:b * 30], times[a * 30:b * 30], None if last else int(times[b * 30]))
        got += p.payloads
        ready += p.ready_ns.tolist()
    assert got == whole.payloads and ready == whole.ready_ns.tolist()


def test_link_timing_without_loss():
    spec = load_scenario("office").link
    link = Link(replace(spec, per_attempt_loss=0.0), [], stream(1, "t"))
    ready = np.arange(200, dtype=np.int64) * 10_000_000
    arrival, delivered, *_ = link.transmit(ready, np.full(200, 30))
    assert delivered.all()
    delay = arrival - ready
    air = (30 + RF_OVERHEAD_BYTES) * BYTE_NS
    fixed = air + spec.latency_ms * 1e6
    assert delay.min() >= fixed and delay.max() <= fixed + spec.jitter_ms * 1e6
    assert np.mean(delay - fixed) == pytest.approx(spec.jitter_ms * 1e6 / 2, rel=0.15)  # uniform backoff


def test_link_queue_serialises_packets():
    spec = load_scenario("office").link
    link = Link(replace(spec, per_attempt_loss=0.0, jitter_ms=0.0), [],
                stream(1, "t"))
    ready = np.zeros(5, dtype=np.int64)  # five packets at once: one after the other
    arrival, *_ = link.transmit(ready, np.full(5, 84))
    service = (84 + RF_OVERHEAD_BYTES) * BYTE_NS + ACK_NS
    assert np.array_equal(np.diff(arrival), np.full(4, service))


def test_loss_and_retry_statistics():
    """Per-attempt loss p and r retries: P(lost) = p^(r+1), retries geometric."""
    spec = load_scenario("office").link
    p, r = 0.3, 2
    link = Link(replace(spec, per_attempt_loss=p, max_retries=r), [],
                stream(7, "t"))
    n = 40_000
    ready = np.arange(n, dtype=np.int64) * 20_000_000
    _, delivered, *_ = link.transmit(ready, np.full(n, 30))
    lost = 1 - delivered.mean()
    assert lost == pytest.approx(p ** (r + 1), abs=4 * math.sqrt(p ** (r + 1) / n))
    outcomes = [link.unicast(i * 20_000_000, 30) for i in range(5000)]
    retries = np.array([o[1] for o in outcomes if o[0]])
    expected = [(1 - p) * p ** k / (1 - p ** (r + 1)) for k in range(r + 1)]
    assert np.bincount(retries, minlength=r + 1) / len(retries) == pytest.approx(expected, abs=0.03)
    failed = [o for o in outcomes if not o[0]]
    assert all(o[1] == r for o in failed)
    # giving up takes all attempts: at least (r + 1) airtimes and ACK waits
    air = (30 + RF_OVERHEAD_BYTES) * BYTE_NS
    assert min(o[2] for o in failed) >= (r + 1) * (air + spec.retry_ms * 1e6)


def test_link_loss_window_drops_everything_inside():
    spec = load_scenario("office").link
    link = Link(spec, [LinkLoss(start_s=1.0, end_s=2.0)], stream(3, "t"))
    ready = np.arange(300, dtype=np.int64) * 10_000_000
    _, delivered, *_ = link.transmit(ready, np.full(300, 30))
    inside = (ready >= 1e9) & (ready < 2e9)
    assert not delivered[inside].any() and delivered[~inside].mean() > 0.99
    assert link.unicast(1_500_000_000, 10)[0] is False


@pytest.fixture(scope="module")
def office_run():
    sc = load_scenario("office")
    return (sc,) + run(sc)


def test_rf_packets_carry_the_sins_stream(office_run):
    sc, w, events = office_run
    rf = [e for e in events if e.port == "xbee"]
    router = w.radios["router"]
    assert all(e.data.src64 == (router["SH"] << 32 | router["SL"]) and e.data.src16 == router["MY"]
               and e.data.options == 0x01 for e in rf)
    sins_stream = port_bytes(events, "sins")
    chunks = b"".join(e.data.data for e in rf)
    if len(rf) == len([e for e in events if e.port == "sins"]):  # nothing lost in this run
        assert chunks == sins_stream
    # every packet arrives after its bytes were written, within the link's worst delay
    starts = {e.data: e.t_ns for e in events if e.port == "sins"}
    frame_end = 30 * CHAR + 3 * CHAR
    for e in rf[:500]:
        t_frame = starts[e.data.data]
        assert t_frame + frame_end < e.t_ns < t_frame + frame_end + 40e6


def test_link_loss_fault_removes_packets_from_the_world(tmp_path):
    sc = variant(tmp_path, "office", 'duration_s = 5.0\n[[faults]]\nkind = "link_loss"\nstart_s = 2.0\nend_s = 3.0\n')
    _, events = run(sc)
    rf_t = np.array([e.t_ns for e in events if e.port == "xbee"])
    assert not np.any((rf_t > 2.02e9) & (rf_t < 3.0e9))
    assert np.sum(rf_t < 2.0e9) > 190 and np.sum(rf_t > 3.02e9) > 190
    assert len([e for e in events if e.port == "sins"]) == 500  # the board never notices


def test_host_traffic_never_changes_the_device_streams():
    sc = load_scenario("office")
    quiet = run(sc, 9)[1]
    from navtwin.emulator.world import World
    busy = World(sc, 9)
    events = []
    for t in range(0, busy.duration_ns, 250_000_000):
        events += busy.advance(t)
        busy.downlinks["xbee"].unicast(t, 40)  # the host sends to the router now and then
    events += busy.advance(busy.duration_ns)
    assert events == quiet


@pytest.mark.parametrize("loss", [0.0, 0.5, 1.0])
def test_a_blocks_air_is_each_packets_attempts_then_the_ack_of_the_received_one(loss):
    """Sender.block against the air written out per attempt: every attempt a packet made
    carries its data frame (MAC seq counting the packets, src16 its own), and an ACK of the
    same seq follows the attempt that was received, one turnaround after its end."""
    from navtwin.emulator.radio import AirFrame, Sender
    from navtwin.protocols import ieee802154, zigbee
    from navtwin.protocols.ieee802154 import TURNAROUND_NS

    spec = replace(load_scenario("office").link, per_attempt_loss=loss, max_retries=3)
    ready = np.arange(300, dtype=np.int64) * 7_000_000
    payloads = [bytes([k % 256]) * (30 if k % 7 else 44) for k in range(300)]
    _, _, _, attempts = Link(spec, [], stream(4, "t")).transmit(ready, [len(p) for p in payloads])
    which = np.flatnonzero(np.arange(300) % 5 != 2)  # the others left out (a router away)
    src16 = [0x1000 + k for k in which.tolist()]
    sender = Sender(0x3A7C)
    sender.sent = 250  # the MAC sequence number wraps within the block
    got = sender.block(attempts, which, src16, 0, [payloads[k] for k in which.tolist()])
    expected = []
    for n, (k, my) in enumerate(zip(which.tolist(), src16)):
        seq = (250 + n) & 0xFF
        psdu = ieee802154.data_frame(seq, 0x3A7C, 0, my, zigbee.data_packet(0, my, 0x1E, seq, seq, payloads[k]))
        air = []
        for a in range(int(attempts.count[k])):
            air.append(AirFrame(int(attempts.on_air_ns[k, a]), psdu))
            if not attempts.lost[k, a]:
                air.append(AirFrame(int(attempts.on_air_ns[k, a] + attempts.air_ns[k]) + TURNAROUND_NS,
                                    ieee802154.ack_frame(seq)))
        expected.append(air)
    assert got == expected and sender.sent == 250 + len(which)
    # frames a packet: 2 when received at once, 5 at the last retry, 4 lost (no ACK)
    assert {len(a) for a in got} == ({2} if loss == 0 else {4} if loss == 1 else {2, 3, 4, 5})


def packetised_by_the_byte(np_bytes: int, ro_ns: float, data: bytes, times, next_byte_ns):
    """The router's packets, byte by byte as its firmware sees them: a packet closes at NP
    bytes, or when the gap after a byte is longer than RO (never at the end of the bytes
    given, when more come at *next_byte_ns*). (ready_ns, payloads, the bytes left open)."""
    ready, payloads, lo = [], [], 0
    after = list(times[1:]) + [math.inf if next_byte_ns is None else next_byte_ns]
    for i, (t, gap_end) in enumerate(zip(times, after)):
        if i + 1 - lo == np_bytes or gap_end - t > ro_ns:
            ready.append(int(t) + (0 if i + 1 - lo == np_bytes else round(ro_ns)))
            payloads.append(data[lo:i + 1])
            lo = i + 1
    return ready, payloads, data[lo:]


@pytest.mark.parametrize("seed", range(4))
def test_the_packets_are_the_routers_byte_by_byte(seed):
    """Random streams (bursts, silences, RO 0..4, NP 1..99) in blocks: the same packets,
    ready times and open bytes as the byte-by-byte router."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        np_bytes, ro = int(rng.integers(1, 100)), int(rng.integers(0, 5))
        router, t, data_all, times_all = Router(np_bytes, ro, CHAR), 0, b"", []
        got_ready, got = [], []
        for block in range(4):
            gaps = rng.choice([87, 87, 87, 200, 300, 1000, 5000], int(rng.integers(0, 300)))
            times = t + np.cumsum(gaps).astype(np.int64)
            t = int(times[-1]) if len(times) else t
            data = rng.integers(0, 256, len(times), dtype=np.uint8).tobytes()
            nxt = None if block == 3 else t + int(rng.choice([87, 500, 5000]))
            p = router.packetise(data, times, nxt)
            got_ready += p.ready_ns.tolist()
            got += p.payloads
            data_all, times_all = data_all + data, times_all + times.tolist()
            t = t if nxt is None else nxt - 87
        ready, payloads, left = packetised_by_the_byte(np_bytes, ro * CHAR, data_all, times_all, None)
        assert (got_ready, got, router._data) == (ready, payloads, left)


def test_a_transmit_requests_frame_has_its_own_radius_and_endpoints():
    """The coordinator's one packet (Sender.frames) with a 0x11's endpoints, cluster, profile
    and radius: its data frame is the builders' with those, not the router's defaults made
    before for the same addresses."""
    from navtwin.emulator.radio import Sender
    from navtwin.protocols import ieee802154, zigbee

    spec = replace(load_scenario("office").link, per_attempt_loss=0.0)
    _, _, _, attempts = Link(spec, [], stream(4, "t")).transmit(np.array([0, 10**7]), [5, 5])
    sender = Sender(0x3A7C)
    plain = sender.frames(attempts, 0, 0, 0x5B21, b"hello")
    aps = dict(src_endpoint=0, dest_endpoint=0, cluster=0x0031, profile=0)
    own = sender.frames(attempts, 1, 0, 0x5B21, b"hello", 5, **aps)
    assert plain[0].psdu == ieee802154.data_frame(0, 0x3A7C, 0x5B21, 0, zigbee.data_packet(
        0x5B21, 0, 0x1E, 0, 0, b"hello"))
    assert own[0].psdu == ieee802154.data_frame(1, 0x3A7C, 0x5B21, 0, zigbee.data_packet(
        0x5B21, 0, 5, 1, 1, b"hello", **aps)) != plain[0].psdu
