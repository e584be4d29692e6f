"""The scheduler: UART timeline, determinism across seeds and speeds, recordings."""
import threading

import numpy as np
import pytest

from navtwin.emulator.clock import serial_queue
from navtwin.emulator.coordinator import SERIAL_TX_BUFFER
from navtwin.emulator.runner import SEC, Emulation, parse_speed
from navtwin.emulator.uart import END, Line, Wire
from navtwin.protocols.serial import wire_ns
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.timing import BINS, MODES
from navtwin.emulator.truth import read_truth_csv
from navtwin.emulator.world import World
from navtwin.protocols import xbee
from navtwin.protocols.ports import names
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import (DecodeError, Frame, XBeeDecoder, XBeeSinsChain, nanoloc_decoder,
                              sins_decoder)

from ..helpers import fifo_permitted

PORTS = names()  # the lab's ports, in its order


@pytest.fixture(scope="module")
def office():
    return load_scenario("office")


def record(directory, scenario, seed=None, stop_after=None, **kw):
    """Record a run; *stop_after* chunks of SINS, then stop it as SIGTERM would."""
    kw.setdefault("speed", None)
    stop = threading.Event()
    with Emulation(scenario, seed, ports=False, record=directory, **kw) as emu:
        if stop_after is not None:
            deliver, count = emu._deliver, []

            def counting(chunk, wall):
                deliver(chunk, wall)
                count.append(chunk.port == "sins")
                if sum(count) >= stop_after:
                    stop.set()

            emu._deliver = counting
        summary = emu.run(stop)
    return Recording(directory), summary


def device_times(rec, port):
    return [(c.offset, len(c.data), c.t_device_ns) for c in rec.chunks(port)]


# -- Line: the UART model ------------------------------------------------------------------

def test_chunks_queue_on_the_wire_and_arrive_whole():
    line = Line("sins", Wire(115200))
    line.put(0, b"a" * 30)
    line.put(1_000_000, b"b" * 10)  # ready while the first is still on the wire
    t30 = wire_ns(30, 115200)
    assert t30 == 2_604_167
    assert line.poll(t30 - 1, 10 * SEC, 10 * SEC) == []  # in flight: not delivered yet
    (first,) = line.poll(t30, 10 * SEC, 10 * SEC)
    assert (first.start_ns, first.end_ns, first.data) == (0, t30, b"a" * 30)
    (second,) = line.poll(10 * SEC, 10 * SEC, 10 * SEC)
    assert (second.start_ns, second.end_ns) == (t30, t30 + wire_ns(10, 115200))


def test_a_chunk_waits_until_everything_that_could_precede_it_is_known():
    line = Line("xbee", Wire(115200))
    line.put(5_000_000, b"answer")
    assert line.poll(6_000_000, known_ns=5_000_000, end_ns=SEC) == []
    assert line.current is None  # an event in [5 ms, ...) may still come from the world
    line.put(5_000_000 - 1, b"earlier")
    line.poll(SEC, known_ns=6_000_000, end_ns=SEC)
    assert line.chunks == 2 and line.bytes == 13


def test_nothing_starts_at_or_after_the_end():
    line = Line("sins", Wire(115200))
    line.put(SEC - 1, b"x" * 30)
    line.put(SEC, b"y")
    out = line.poll(2 * SEC, 2 * SEC, SEC)
    assert [c.data for c in out] == [b"x" * 30]  # started before the end, so it completes
    assert line.next_ns() == SEC - 1 + wire_ns(30, 115200) and not line.busy(SEC)


class _Rate(Wire):
    """A device whose rate changes after a marked item, like the coordinator after BD."""

    def __init__(self):
        super().__init__(115200)

    def render(self, t, item):
        if item == b"":
            return b""
        if item == b"BD":
            self.baud = 9600
        return item


def test_rate_change_applies_to_the_following_chunks_and_empty_renders_are_skipped():
    line = Line("xbee", _Rate())
    for item in (b"BD", b"", b"0123456789"):
        line.put(0, item)
    out = line.poll(SEC, SEC, SEC)
    assert [c.data for c in out] == [b"BD", b"0123456789"]
    assert out[0].end_ns - out[0].start_ns == wire_ns(2, 115200)
    assert out[1].end_ns - out[1].start_ns == wire_ns(10, 9600) == 10_416_667


class _Bounded(Wire):
    """A device with a 10-byte transmit buffer."""

    @staticmethod
    def admit(t_ns, item, queued):
        return None if queued + len(item) > 10 else len(item)


def test_a_bounded_buffer_drops_what_does_not_fit_when_it_arrives():
    line = Line("xbee", _Bounded(115200))
    line.put(0, b"a" * 6)
    line.put(1, b"b" * 5)  # "a" is still on the wire: 6 + 5 > 10
    line.put(wire_ns(6, 115200), b"c" * 5)  # "a" has just arrived: room again
    assert [c.data for c in line.poll(SEC, SEC, SEC)] == [b"a" * 6, b"c" * 5]
    assert line.queued == 0


@pytest.mark.parametrize("text,value", [("realtime", 1.0), ("max", None), ("10", 10.0),
                                        ("0.5", 0.5)])
def test_parse_speed(text, value):
    assert parse_speed(text) == value


@pytest.mark.parametrize("text", ["fast", "0", "-2", "inf", "nan"])
def test_bad_speed_is_one_line_with_the_fix(text):
    with pytest.raises(ValueError) as e:
        parse_speed(text)
    assert "\n" not in str(e.value) and str(e.value).startswith("speed: ")


# -- whole runs ----------------------------------------------------------------------------

def test_uart_schedule_matches_an_independent_queue_model(office):
    """Start of every chunk = max(device's event time, end of the previous chunk), computed
    here with E1's vectorised max-plus queue from the world's own events."""
    emu = Emulation(office, speed=None, ports=False, duration_s=3)
    starts = {p: [] for p in PORTS}
    emu._deliver = lambda chunk, wall: starts[chunk.port].append((chunk.start_ns, chunk.data))
    emu.run()
    events = World(office).advance(3 * SEC)
    for port in ("sins", "nanoloc"):
        mine = [e for e in events if e.port == port]
        ready = np.array([e.t_ns for e in mine])
        dur = np.array([wire_ns(len(e.data), 115200) for e in mine])
        expect_start, _ = serial_queue(ready, dur, 0)
        assert [s for s, _ in starts[port]] == expect_start.tolist()
        assert [d for _, d in starts[port]] == [e.data for e in mine]


def test_same_seed_same_bytes_other_seed_different(tmp_path, office):
    a, _ = record(tmp_path / "a", office, 5, duration_s=4)
    b, _ = record(tmp_path / "b", office, 5, duration_s=4)
    c, _ = record(tmp_path / "c", office, 6, duration_s=4)
    for port in PORTS:
        assert a.read_bytes(port) == b.read_bytes(port)
        assert device_times(a, port) == device_times(b, port)
        assert a.read_bytes(port) != c.read_bytes(port)


@pytest.mark.parametrize("mode", [m for m in MODES if m != "fifo" or fifo_permitted()])
def test_paced_and_max_speed_give_identical_recordings(tmp_path, office, mode):
    fast, fast_summary = record(tmp_path / "max", office, duration_s=2)
    paced, summary = record(tmp_path / "x25", office, duration_s=2, speed=25.0, timing=mode)
    assert not summary["interrupted"]
    for port in PORTS:
        assert fast.read_bytes(port) == paced.read_bytes(port)
        assert device_times(fast, port) == device_times(paced, port)
    walls = [c.t_wall_ns for c in paced.chunks("sins")]
    assert all(w is not None for w in walls) and walls == sorted(walls)
    assert all(c.t_wall_ns is None for c in fast.chunks("sins"))
    # the paced run's mode and its lateness histogram: every chunk written, counted once
    assert summary["timing"] == paced.meta["timing"] == mode
    for port in PORTS:
        late = summary["ports"][port]["late"]
        assert list(late) == list(BINS) and paced.meta["lateness"][port] == late
        assert sum(late.values()) == summary["ports"][port]["frames"] \
            == len(list(paced.chunks(port))) > 0
    assert "timing" not in fast.meta and "lateness" not in fast.meta
    assert "late" not in fast_summary["ports"]["sins"]


def test_recording_decodes_into_clean_consistent_streams(tmp_path, office):
    rec, summary = record(tmp_path / "r", office, duration_s=5)
    sins = sins_decoder().decode(rec.read_bytes("sins"))
    assert all(isinstance(f, Frame) for f in sins) and len(sins) == 500
    seqs = [f.fields["seq"] for f in sins]
    assert np.all(np.diff(seqs) == 1)
    assert summary["ports"]["sins"]["frames"] == 500
    reports = nanoloc_decoder().decode(rec.read_bytes("nanoloc"))
    assert reports and all(isinstance(f, Frame) for f in reports)
    chain = XBeeSinsChain(escaped=True)
    events = chain.decode(rec.read_bytes("xbee"))
    assert not [e for e in events if isinstance(e, DecodeError)]
    modem = [e.fields["status"] for e in events if e.format == "xbee" and e.type == 0x8A]
    assert modem == [0x00, 0x06]
    via_radio = [e for e in events if e.format == "sins"]
    by_seq = {f.fields["seq"]: f.raw for f in sins}
    assert len(via_radio) > 450  # a few packets may be lost on the link
    assert all(by_seq[f.fields["seq"]] == f.raw for f in via_radio)


def test_recording_metadata_scenario_and_truth(tmp_path, office):
    rec, _ = record(tmp_path / "r", office, 9, duration_s=2)
    meta = rec.meta
    assert (meta["scenario"], meta["seed"], meta["speed"], meta["duration_s"]) == \
        ("office", 9, "max", 2.0)
    assert meta["ports"] == {"sins": {"baud": 115200}, "nanoloc": {"baud": 115200},
                             "xbee": {"baud": 115200, "api_mode": 2}}
    assert load_scenario(tmp_path / "r" / "scenario.toml").to_toml() == office.to_toml()
    truth = read_truth_csv(tmp_path / "r" / "truth.csv")
    assert len(truth) == 2000 and truth["t"][-1] == 1_999_000_000


def test_stopped_run_records_a_prefix_of_the_full_run(tmp_path, office):
    full, _ = record(tmp_path / "full", office, duration_s=6)
    part, summary = record(tmp_path / "part", office, duration_s=6, speed=5.0, stop_after=150)
    assert summary["interrupted"] and 1.4 < summary["virtual_s"] < 6
    assert part.meta["interrupted"]
    for port in PORTS:
        cut = part.read_bytes(port)
        assert cut and full.read_bytes(port).startswith(cut)
    truth = read_truth_csv(tmp_path / "part" / "truth.csv")
    assert abs(len(truth) - summary["virtual_s"] * 1000) <= 1


def test_duration_beyond_the_scenario_is_one_line_with_the_fix(office):
    with pytest.raises(ValueError) as e:
        Emulation(office, speed=None, ports=False, duration_s=office.duration_s + 1)
    assert "\n" not in str(e.value) and str(e.value).startswith("duration: ") and "office" in str(e.value)


def test_host_answers_land_between_frames_never_inside(office):
    """An AT query arriving while the coordinator's UART is busy waits for the frame in
    progress; the stream stays decodable."""
    emu = Emulation(office, speed=None, ports=False, duration_s=2)
    out = bytearray()
    emu._deliver = lambda chunk, wall: out.extend(chunk.data) if chunk.port == "xbee" else None
    # a query at 1.0 s, straight into the coordinator as the PTY path would pass it
    for o in emu.coordinators["xbee"].host(SEC, xbee.build(0x08, True, frame_id=1, command=b"VR",
                                                  parameter=b"")):
        emu.lines["xbee"].put(o.t_ns, o.item)
    emu.run()
    frames = XBeeSinsChain(escaped=True).decode(bytes(out))
    assert not [e for e in frames if isinstance(e, DecodeError)]
    answers = [e for e in frames if e.format == "xbee" and e.type == 0x88]
    assert len(answers) == 1 and answers[0].fields["value"] == b"\x21\xa7"


def test_api_mode_1_scenario_sends_unescaped_frames(tmp_path):
    toml = tmp_path / "api1.toml"
    toml.write_text('base = "office"\nname = "office-api1"\n\n[xbee.coordinator]\nAP = 1\n')
    sc = load_scenario(toml)
    rec, _ = record(tmp_path / "r", sc, duration_s=2)
    assert rec.meta["ports"]["xbee"] == {"baud": 115200, "api_mode": 1}
    raw = rec.read_bytes("xbee")
    events = XBeeSinsChain(escaped=False).decode(raw)
    assert not [e for e in events if isinstance(e, DecodeError)]
    assert sum(e.format == "sins" for e in events) > 150
    # the same frames as in API mode 2, only without escapes
    escaped, _ = record(tmp_path / "r2", load_scenario("office"), duration_s=2)
    frames2 = XBeeDecoder(escaped=True).decode(escaped.read_bytes("xbee"))
    frames1 = XBeeDecoder(escaped=False).decode(raw)
    assert [(f.type, f.fields) for f in frames1] == [(f.type, f.fields) for f in frames2]
    assert len(raw) < len(escaped.read_bytes("xbee"))


# -- the coordinator's bounded serial transmit buffer -----------------------------------------

def drive(emu, host, step_ns=1_000_000):
    """Run *emu* in virtual time with the host's bytes ``[(t_ns, data)]`` reaching the
    coordinator at their times, as the PTY path passes them; polls every *step_ns*.
    Returns each port's chunks and the most bytes ever queued on the xbee line."""
    host = sorted(host)
    chunks, most = {p: [] for p in PORTS}, 0
    t = 0
    while t < END:
        t = t + step_ns if t < emu.end_ns else END  # then what is still on the wire
        emu._enqueue(emu.world.advance(min(t, emu.end_ns)))
        while host and host[0][0] <= t:
            for out in emu.coordinators["xbee"].host(*host.pop(0)):
                emu.lines["xbee"].put(out.t_ns, out.item)
        for name, line in emu.lines.items():
            chunks[name] += line.poll(t, t, emu.end_ns)
        most = max(most, emu.lines["xbee"].queued)
    return chunks, most


def bd(value, fid):
    return xbee.build(0x08, True, frame_id=fid, command=b"BD", parameter=bytes((value,)))


def test_a_slow_host_line_drops_rf_packets_and_answers_stay_prompt(office):
    """Issue 7 point 8: ATBD3 (9600) with the RF data at ~4.6 kB/s, then ATBD7 10 s later.
    The ATBD7 answer comes within a second, the queue stays within the buffer, and the SINS
    data after it is fresh (compared with the same samples on the direct SINS line)."""
    emu = Emulation(office, speed=None, ports=False, duration_s=16)
    chunks, most = drive(emu, [(1 * SEC, bd(3, 1)), (11 * SEC, bd(7, 2))])
    sins_at = {f.fields["seq"]: c.end_ns  # when the direct line delivered each sample
               for c in chunks["sins"] for f in sins_decoder().decode(c.data)}
    chain = XBeeSinsChain(escaped=True)
    answers, ages = {}, []
    for c in chunks["xbee"]:
        for ev in chain.feed(c.data):
            if ev.format == "xbee" and ev.type == 0x88:
                answers[ev.fields["frame_id"]] = c.end_ns
            elif ev.format == "sins" and 2 in answers:
                ages.append(c.end_ns - sins_at[ev.fields["seq"]])
    assert not [e for e in chain.flush() if isinstance(e, DecodeError)]
    assert answers[2] - 11 * SEC < SEC
    assert most <= SERIAL_TX_BUFFER + 16  # RF packets within the buffer, plus an answer
    assert ages and max(ages[:20]) < SEC
    dropped = emu.summary()["ports"]["xbee"]["dropped_tx_buffer"]
    assert dropped == emu.coordinators["xbee"].dropped_tx_buffer > 300  # most of the 10 s at 9600


def test_what_a_slow_line_drops_does_not_depend_on_when_the_loop_polls(office):
    host = [(1 * SEC, bd(3, 1))]
    runs = []
    for step in (1_000_000, 37_000_000):
        emu = Emulation(office, speed=None, ports=False, duration_s=3)
        chunks, _ = drive(emu, host, step)
        runs.append(([(c.start_ns, c.data) for c in chunks["xbee"]],
                     emu.coordinators["xbee"].dropped_tx_buffer))
    assert runs[0] == runs[1] and runs[0][1] > 50
