"""Line fault kinds: what each does to a known stream, byte for byte; its rate against the
configured one (bounds that fail on a wrong rate); the ledger explaining every difference
between the faulted and the clean stream; determinism; the schedule; the to_device path;
the ledger in a recording; ``--fault`` on the command line."""
from __future__ import annotations

import difflib
import json
import math
import threading

import numpy as np
import pytest

from navtwin.emulator.faults import Fault
from navtwin.emulator.faults.line import Gaps
from navtwin.emulator.ledger import Ledger
from navtwin.emulator.rng import stream
from navtwin.emulator.runner import Emulation, RunError
from navtwin.emulator.scenario import ScenarioError
from navtwin.emulator.uart import END, Inbound, Line, LineWrapper, Wire
from navtwin.protocols.ports import names
from navtwin.protocols.recording import FAULTS, Recording, RecordingError
from navtwin.protocols.serial import wire_ns

from ..helpers import navtwin
from .world_helpers import variant

PORTS = names()  # the lab's ports, in its order

SEC = 1_000_000_000
MS = 1_000_000
BAUD = 115200
Z = 4.5  # sigmas: a right rate passes (p ~ 7e-6 to fail), a rate 20 % off does not


def clean_chunks(n: int, size: int = 30, period_ns: int = 10 * MS) -> list[tuple[int, bytes]]:
    """n chunks of *size* random bytes every *period_ns*; neighbouring bytes always differ
    (so a removal has one place an independent diff can find)."""
    data = (np.cumsum(np.random.default_rng(0).integers(1, 256, n * size)) % 256).astype("u1")
    return [(k * period_ns, data[k * size:(k + 1) * size].tobytes()) for k in range(n)]


def through(kind: str, chunks, seed: int = 1, after_ns: int = SEC, **settings):
    """The chunks a Line with one fault of *kind* delivers in a run that ends *after_ns*
    after the last chunk is ready, and its ledger entries."""
    settings = {"start_s": 0.0, "end_s": 1e6, **settings}
    fault = Fault.KINDS.get(kind)(port="sins", **settings)
    wrapper = fault.wrapper(stream(seed, "test"))
    wrapper.kind, wrapper.fault_index = kind, 0
    ledger = Ledger()
    line = Line("sins", Wire(BAUD), [wrapper], ledger=ledger)
    for t, data in chunks:
        line.put(t, data)
    end = chunks[-1][0] + after_ns
    return line.poll(1 << 60, 1 << 60, end), ledger.entries


def joined(chunks) -> bytes:
    return b"".join(c.data if hasattr(c, "data") else c[1] for c in chunks)


def replay(clean: bytes, faulted: bytes, entries) -> bytes:
    """The faulted stream rebuilt from the clean one and the ledger alone (bytes a fault
    made up are taken from *faulted* at the entry's range)."""
    out, i = bytearray(), 0
    for e in entries:
        n = e["start"] - len(out)
        assert n >= 0, "entries in stream order"
        out += clean[i:i + n]
        i += n
        kind, size = e["kind"], e["end"] - e["start"]
        if kind == "bit_errors":
            out.append(clean[i] ^ e["mask"])
            i += 1
        elif kind == "byte_duplicate":
            out.append(out[-1])
        elif kind == "byte_insert":
            out.append(e["value"])
        elif kind == "garbage":
            out += faulted[e["start"]:e["end"]]
        elif kind == "stuck":
            out += clean[i:i + size]
            i += size
        i += e.get("removed", 0)
    return bytes(out + clean[i:])


def within(k: float, mean: float, var: float) -> bool:
    return abs(k - mean) <= Z * math.sqrt(var)


# -- per-byte kinds: exact, ledger = diff, rate --------------------------------------------
N = 2000  # chunks of 30 bytes: 60 000 bytes, 480 000 bits


@pytest.mark.parametrize("kind,settings,per_bit", [
    ("bit_errors", {"ber": 2e-3}, True),
    ("byte_drop", {"probability": 0.01}, False),
    ("byte_duplicate", {"probability": 0.01}, False),
    ("byte_insert", {"probability": 0.01}, False),
])
def test_a_per_byte_kind_hits_at_its_rate_and_the_ledger_explains_every_byte(kind, settings,
                                                                             per_bit):
    chunks = clean_chunks(N)
    clean = joined(chunks)
    out, entries = through(kind, chunks, **settings)
    faulted = joined(out)
    assert replay(clean, faulted, entries) == faulted
    p = settings.get("ber", settings.get("probability"))
    units = 8 * len(clean) if per_bit else len(clean)
    hits = (sum(bin(e["mask"]).count("1") for e in entries) if per_bit
            else sum(e.get("removed", 1) for e in entries))
    assert within(hits, units * p, units * p * (1 - p)), (hits, units * p)
    assert [(c.start_ns, len(c.data) > 0) for c in out] == [(t, True) for t, _ in chunks]
    assert all(kind != "bit_errors" or e["t_ns"] == chunks[e["start"] // 30][0] for e in entries)
    if kind == "byte_drop":  # an independent diff names the same removals
        ops = difflib.SequenceMatcher(None, clean, faulted, autojunk=False).get_opcodes()
        removed = [(j1, i2 - i1) for tag, i1, i2, j1, _ in ops if tag == "delete"]
        assert all(tag in ("equal", "delete") for tag, *_ in ops)
        assert removed == [(e["start"], e["removed"]) for e in entries]


def test_bit_errors_flip_every_bit_position_alike_and_never_more_than_drawn():
    chunks = clean_chunks(N)
    out, entries = through("bit_errors", chunks, ber=5e-3)
    counts = np.zeros(8)
    for e in entries:
        for b in range(8):
            counts[b] += e["mask"] >> b & 1
    expect = counts.sum() / 8
    chi2 = ((counts - expect) ** 2 / expect).sum()
    assert chi2 < 24.3, counts  # chi-square, 7 degrees of freedom, p = 0.001
    clean, faulted = joined(chunks), joined(out)
    assert len(faulted) == len(clean)
    diff = [i for i, (a, b) in enumerate(zip(clean, faulted)) if a != b]
    assert diff == [e["start"] for e in entries]


def test_gaps_are_geometric_and_carry_across_chunks():
    whole = Gaps(np.random.default_rng(3), 0.05).take(10_000)
    g = Gaps(np.random.default_rng(3), 0.05)
    parts, base = [], 0
    for n in (1, 7, 500, 3, 9489):
        parts += [base + p for p in g.take(n)]
        base += n
    assert parts == whole
    assert within(len(whole), 500, 10_000 * 0.05 * 0.95)


def test_a_known_drop_duplicate_and_insert_byte_for_byte():
    chunks = [(0, b"abcdefgh")]
    out, entries = through("byte_drop", chunks, probability=1.0)
    assert out == [] and entries == [dict(entries[0], start=0, end=0, removed=8)]
    out, entries = through("byte_duplicate", chunks, probability=1.0)
    assert joined(out) == b"aabbccddeeffgghh"
    assert [(e["start"], e["end"]) for e in entries] == [(i, i + 1) for i in range(1, 16, 2)]
    out, entries = through("byte_insert", chunks, probability=1.0)
    data = joined(out)
    assert data[1::2] == b"abcdefgh" and [e["value"] for e in entries] == list(data[0::2])
    assert out[0].end_ns == wire_ns(16, BAUD)  # the line times what the fault made


# -- garbage ---------------------------------------------------------------------------------
def test_garbage_bursts_come_between_chunks_at_their_rate_and_length():
    chunks = clean_chunks(3000)  # 30 s
    clean = joined(chunks)
    out, entries = through("garbage", chunks, rate_hz=20.0, min_bytes=2, max_bytes=9)
    faulted = joined(out)
    assert replay(clean, faulted, entries) == faulted
    assert within(len(entries), 20 * 30, 20 * 30)  # Poisson: variance = mean
    sizes = [e["end"] - e["start"] for e in entries]
    assert min(sizes) >= 2 and max(sizes) <= 9 and within(np.mean(sizes), 5.5, 8.25 / len(sizes))
    offsets = np.cumsum([0] + [len(c.data) for c in out])
    burst = {e["start"]: e for e in entries}
    assert len(burst) == len(entries)
    prev_end = 0
    for c, at in zip(out, offsets):
        if at in burst:  # a burst is a chunk of its own, at its time or when the line frees
            e = burst.pop(at)
            assert len(c.data) == e["end"] - e["start"] and c.start_ns == e["t_ns"]
            assert c.start_ns == max(e["due_ns"], prev_end)
        assert c.start_ns >= prev_end
        prev_end = c.end_ns
    assert not burst
    assert [c.data for c, at in zip(out, offsets) if at not in {e["start"] for e in entries}] \
        == [d for _, d in chunks]


def test_garbage_only_inside_its_episodes():
    chunks = clean_chunks(1000)  # 10 s
    _, entries = through("garbage", chunks, rate_hz=50.0, start_s=1.0, end_s=2.0, repeat_s=4.0)
    assert entries and all(1 <= e["due_ns"] / SEC % 4 < 2 for e in entries)
    assert within(len(entries), 50 * 3, 50 * 3)  # episodes at 1, 5 and 9 s


# -- burst loss ------------------------------------------------------------------------------
def test_burst_loss_follows_its_two_state_model():
    p_gb, p_bg = 0.01, 0.1
    chunks = [(0, bytes(200_000))]
    out, entries = through("burst_loss", chunks, p_good_to_bad=p_gb, p_bad_to_good=p_bg)
    lost = sum(e["removed"] for e in entries)
    assert abs(lost / 200_000 - p_gb / (p_gb + p_bg)) < 0.15 * p_gb / (p_gb + p_bg)
    assert abs(np.mean([e["removed"] for e in entries]) - 1 / p_bg) < 0.15 / p_bg
    assert len(joined(out)) == 200_000 - lost


def test_burst_loss_per_chunk_drops_whole_chunks_and_the_ledger_explains_it():
    chunks = clean_chunks(3000)
    clean = joined(chunks)
    out, entries = through("burst_loss", chunks, unit="chunk", p_good_to_bad=0.05,
                           p_bad_to_good=0.5, loss_good=0.1, loss_bad=0.9)
    faulted = joined(out)
    assert replay(clean, faulted, entries) == faulted
    assert all(e["removed"] == 30 and e["start"] % 30 == 0 for e in entries)
    pi_bad = 0.05 / 0.55
    rate = pi_bad * 0.9 + (1 - pi_bad) * 0.1
    assert abs(len(entries) / 3000 - rate) < 0.2 * rate


# -- timing kinds: latency, bandwidth, slicing, stuck ---------------------------------------
def test_latency_shifts_a_stream_without_slowing_it_and_keeps_it_in_order():
    chunks = clean_chunks(500)
    out, entries = through("latency", chunks, delay_s=0.05)
    assert [c.start_ns for c in out] == [t + 50 * MS for t, _ in chunks]
    assert joined(out) == joined(chunks)
    assert [(e["start"], e["end"], e["delay_ns"]) for e in entries] == \
        [(30 * k, 30 * k + 30, 50 * MS) for k in range(500)]
    ready = [t for t, _ in chunks]
    out, entries = through("latency", chunks, delay_s=0.02, jitter_s=0.003)
    delays = np.array([c.start_ns for c in out]) - ready  # no chunk waits behind another
    assert delays.min() >= 17 * MS and delays.max() <= 23 * MS
    assert abs(delays.mean() - 20 * MS) < 0.5 * MS  # uniform +- 3 ms: sd of the mean 0.08 ms
    assert [e["delay_ns"] for e in entries] == delays.tolist()
    out, entries = through("latency", chunks, delay_s=0.02, jitter_s=0.015)
    assert all(b.start_ns >= a.end_ns for a, b in zip(out, out[1:]))  # in order, no overlap
    assert all(5 * MS <= c.start_ns - r <= 35 * MS + 3 * MS for c, r in zip(out, ready))
    assert joined(out) == joined(chunks)


def test_bandwidth_caps_the_throughput():
    chunks = clean_chunks(1000)  # 3000 B/s offered
    out, entries = through("bandwidth", chunks, bytes_per_s=1500.0, after_ns=20 * SEC)
    assert joined(out) == joined(chunks)
    assert [c.end_ns for c in out] == [math.ceil(30e9 / 1500) * (k + 1) for k in range(1000)]
    out, _ = through("bandwidth", chunks, bytes_per_s=6000.0)  # above the offered rate
    assert [c.end_ns - t for c, (t, _) in zip(out, chunks)] == [5 * MS] * 1000
    out, entries = through("bandwidth", chunks, bytes_per_s=20_000.0)  # above the baud's
    assert [c.start_ns for c in out] == [t for t, _ in chunks] and entries == []


def test_slicing_sends_a_chunk_in_pieces_with_gaps():
    out, entries = through("slicing", [(0, bytes(range(20))), (SEC, b"x")], piece_bytes=8,
                           gap_s=0.002)
    w8, w4 = wire_ns(8, BAUD), wire_ns(4, BAUD)
    assert [(c.start_ns, c.data) for c in out] == [
        (0, bytes(range(8))), (w8 + 2 * MS, bytes(range(8, 16))),
        (2 * (w8 + 2 * MS), bytes(range(16, 20))), (SEC, b"x")]
    assert out[2].end_ns == 2 * (w8 + 2 * MS) + w4
    assert [(e["start"], e["end"], e["pieces"]) for e in entries] == [(0, 20, [8, 8, 4])]


def test_slicing_with_variation_and_probability():
    chunks = clean_chunks(2000)
    out, entries = through("slicing", chunks, probability=0.3, piece_bytes=6, piece_variation=3)
    assert joined(out) == joined(chunks)
    assert within(len(entries), 600, 2000 * 0.3 * 0.7)
    sizes = [s for e in entries for s in e["pieces"][:-1]]  # the last piece is what is left
    assert min(sizes) >= 3 and max(sizes) <= 9
    assert len(out) == 2000 + sum(len(e["pieces"]) - 1 for e in entries)


def test_stuck_holds_its_buffer_loses_the_overrun_and_delivers_at_the_end():
    chunks = clean_chunks(300)  # 3 s
    clean = joined(chunks)
    out, entries = through("stuck", chunks, start_s=1.0, end_s=1.5, buffer_bytes=40)
    inside = [k for k, (t, _) in enumerate(chunks) if SEC <= t < 1.5 * SEC]
    held = b"".join(chunks[k][1] for k in inside)
    first, last = inside[0], inside[-1]
    assert [c.data for c in out[:first]] == [d for _, d in chunks[:first]]
    release = out[first]
    assert (release.start_ns, release.data) == (1.5 * SEC, held[:40])
    assert [c.data for c in out[first + 1:]] == [d for _, d in chunks[last + 1:]]
    (e,) = entries
    assert (e["start"], e["end"], e["removed"], e["held_ns"]) == (
        30 * first, 30 * first + 40, len(held) - 40, SEC // 2)
    assert replay(clean, joined(out), entries) == joined(out)
    _, entries = through("stuck", chunks, start_s=1.0, end_s=1.5, buffer_bytes=0)
    assert entries[0]["end"] == entries[0]["start"] and entries[0]["removed"] == len(held)


def test_stuck_on_a_coordinator_line_fills_its_bounded_buffer_too():
    # periodic episodes: each one releases its own buffer
    chunks = clean_chunks(400)
    out, entries = through("stuck", chunks, start_s=0.5, end_s=0.7, repeat_s=1.0, until_s=3.0)
    assert [e["t_ns"] for e in entries] == [int(0.7 * SEC), int(1.7 * SEC), int(2.7 * SEC)]
    assert all(not (0.5 <= (c.start_ns / SEC) % 1 < 0.7) or c.start_ns / SEC >= 3
               for c in out)


# -- the seam ----------------------------------------------------------------------------------
class _Release(LineWrapper):
    """Asks to send b"!" at 5 ms; a second wrapper after it sees the release."""

    def __init__(self):
        self.due = 5 * MS

    def due_ns(self):
        return self.due

    def release(self, t_ns, baud):
        self.due = None
        self.mark(t_ns, 0, 1)
        return t_ns, b"!"


class _Upper(LineWrapper):
    def send(self, start_ns, data, baud):
        return start_ns, data.upper()


def test_a_release_goes_ahead_of_a_chunk_due_at_the_same_time_and_through_later_wrappers():
    ledger = Ledger()
    first = _Release()
    first.kind = "x"
    line = Line("sins", Wire(BAUD), [first, _Upper()], ledger=ledger)
    line.put(5 * MS, b"ab")
    line.put(0, b"cd")
    out = line.poll(SEC, SEC, SEC)
    assert [(c.start_ns, c.data) for c in out] == [
        (0, b"CD"), (5 * MS, b"!"), (5 * MS + wire_ns(1, BAUD), b"AB")]
    assert [(e["kind"], e["start"], e["t_ns"]) for e in ledger.entries] == [("x", 2, 5 * MS)]
    assert not line.busy(END) and line.next_ns() is None


def test_pieces_held_past_the_end_of_the_run_are_not_sent():
    out, _ = through("slicing", [(SEC - 1, bytes(30))], piece_bytes=10, gap_s=0.4)
    assert len(out) == 3  # all before the end
    fault = Fault.KINDS.get("slicing")(port="sins", start_s=0.0, end_s=10.0, piece_bytes=10, gap_s=0.5)
    ledger = Ledger()
    line = Line("sins", Wire(BAUD), [fault.wrapper(stream(1, "t"))], ledger=ledger)
    line.put(SEC - 1, bytes(30))
    line.put(SEC + 1, bytes(30))  # after the end: never starts, no entry
    assert [len(c.data) for c in line.poll(5 * SEC, 5 * SEC, SEC)] == [10]
    assert not line.busy(SEC) and line.queued == 0
    (e,) = ledger.entries  # the range is what was sent
    assert (e["start"], e["end"], e["pieces"]) == (0, 10, [10, 10, 10])


# -- schedule ----------------------------------------------------------------------------------
def test_periodic_episodes_in_active_on_arrays_and_their_helpers():
    f = Fault.KINDS.get("anchor_outage")(anchor=1, start_s=1.0, end_s=1.25, repeat_s=1.0,
                                     until_s=3.5)
    t = np.arange(0, 6 * SEC, 50 * MS)
    on = f.active(t)
    expect = (t >= SEC) & ((t % SEC) < 250 * MS) & (t < 4 * SEC)
    assert np.array_equal(on, expect)
    assert f.active(2 * SEC + 100 * MS) and not f.active(2 * SEC + 250 * MS)
    assert f.episode_end(2 * SEC + 7) == 2 * SEC + 250 * MS
    assert f.next_active(0) == SEC and f.next_active(SEC + 300 * MS) == 2 * SEC
    assert f.next_active(3 * SEC + 300 * MS) is None  # no episode starts at or after 3.5 s
    assert f.at_active(300 * MS) == 2 * SEC + 50 * MS and f.at_active(750 * MS) is None
    once = Fault.KINDS.get("anchor_outage")(anchor=1, start_s=1.0, end_s=2.0)
    assert once.next_active(3 * SEC) is None and once.at_active(2 * SEC) is None


@pytest.mark.parametrize("extra,words", [
    ("repeat_s = 0.5", "repeat_s must be longer"),
    ("until_s = 3.0", "until_s needs repeat_s"),
    ('kind2 = 1', "unknown key"),
])
def test_bad_schedules_get_one_line(tmp_path, extra, words):
    with pytest.raises(ScenarioError, match=words):
        variant(tmp_path, "office", '[[faults]]\nkind = "latency"\nport = "sins"\n'
                                    f"start_s = 1.0\nend_s = 2.0\n{extra}\n")


def test_a_periodic_device_fault_acts_in_every_episode(tmp_path):
    sc = variant(tmp_path, "office", '[[faults]]\nkind = "link_loss"\nstart_s = 0.5\n'
                                     "end_s = 1.0\nrepeat_s = 2.0\n")
    got = []
    with Emulation(sc, 3, speed=None, ports=False, duration_s=6.0, sink=got.append) as emu:
        emu.run()
    times = np.array([c.start_ns for c in got if c.port == "xbee"]) / SEC
    assert len(times) > 100
    for k in range(3):  # nothing reaches the coordinator in the link's down time
        assert not np.any((times >= 2 * k + 0.52) & (times < 2 * k + 1.0))
        assert np.any((times >= 2 * k + 1.1) & (times < 2 * k + 1.4))


# -- direction -----------------------------------------------------------------------------------
class _Baud:
    baud = BAUD


def test_to_device_bytes_reach_the_device_through_the_same_wrappers():
    plain = Inbound("xbee", _Baud())
    plain.put(7 * MS, b"hello")
    assert plain.poll(7 * MS) == [(7 * MS, b"hello")] and plain.next_ns() is None
    fault = Fault.KINDS.get("latency")(port="xbee", direction="to_device", start_s=0.0, end_s=1.0,
                                   delay_s=0.01)
    wrapper = fault.wrapper(stream(1, "t"))
    wrapper.kind, wrapper.direction = "latency", "to_device"
    ledger = Ledger()
    late = Inbound("xbee", _Baud(), [wrapper], ledger=ledger)
    late.put(7 * MS, b"hello")
    assert late.poll(7 * MS) == [] and late.next_ns() == 17 * MS
    assert late.poll(20 * MS) == [(17 * MS, b"hello")]
    assert [(e["direction"], e["start"], e["end"]) for e in ledger.entries] == \
        [("to_device", 0, 5)]
    stuck = Fault.KINDS.get("stuck")(port="xbee", direction="to_device", start_s=0.0, end_s=0.5,
                                 buffer_bytes=3)
    inbound = Inbound("xbee", _Baud(), [stuck.wrapper(stream(1, "t"))])
    inbound.put(7 * MS, b"hello")
    assert inbound.poll(SEC // 2 - 1) == [] and inbound.next_ns() == SEC // 2
    assert inbound.poll(SEC) == [(SEC // 2 + wire_ns(3, BAUD), b"hel")]


def test_the_emulation_puts_to_device_faults_on_what_the_host_writes(tmp_path):
    sc = variant(tmp_path, "office", '[[faults]]\nkind = "byte_drop"\nport = "xbee"\n'
                                     'direction = "to_device"\nprobability = 1.0\n'
                                     "start_s = 0.0\nend_s = 1.0\n")
    with Emulation(sc, 1, speed=None, ports=False, duration_s=2.0) as emu:
        assert len(emu.inbounds["xbee"].wrappers) == 1 and not emu.lines["xbee"].wrappers
        at_frame = bytes.fromhex("7E00040801414951") + b"\x00"  # any bytes: all dropped
        emu.inbounds["xbee"].put(10 * MS, at_frame)
        emu._to_device(10 * MS)
        emu.run()
    (e,) = emu.ledger.entries
    assert (e["port"], e["direction"], e["removed"], e["fault"]) == ("xbee", "to_device", 9, 0)
    with Emulation(variant(tmp_path, "office", ""), 1, speed=None, ports=False,
                   duration_s=0.1) as emu:
        with pytest.raises(RunError, match="ignores what the host writes"):
            emu.wrap("sins", LineWrapper(), "to_device")


def test_to_device_is_refused_on_a_port_whose_device_does_not_read(tmp_path):
    with pytest.raises(ScenarioError, match='to_device on nanoloc.*direction = "to_host"'):
        variant(tmp_path, "office", '[[faults]]\nkind = "byte_drop"\nport = "nanoloc"\n'
                                    'direction = "to_device"\nstart_s = 0.0\nend_s = 1.0\n')


# -- whole runs: determinism, other ports, the recorded ledger -----------------------------------
EVERY_KIND = """
[[faults]]
kind = "anchor_outage"
anchor = 1
start_s = 0.2
end_s = 0.4
[[faults]]
kind = "bit_errors"
port = "sins"
ber = 0.001
start_s = 0.0
end_s = 3.0
[[faults]]
kind = "byte_drop"
port = "nanoloc"
probability = 0.01
start_s = 0.5
end_s = 0.6
repeat_s = 0.3
[[faults]]
kind = "byte_duplicate"
port = "xbee"
probability = 0.005
start_s = 0.0
end_s = 3.0
[[faults]]
kind = "byte_insert"
port = "sins"
probability = 0.002
start_s = 1.0
end_s = 2.0
[[faults]]
kind = "garbage"
port = "nanoloc"
rate_hz = 5.0
start_s = 0.0
end_s = 3.0
[[faults]]
kind = "burst_loss"
port = "xbee"
p_good_to_bad = 0.002
start_s = 0.0
end_s = 3.0
[[faults]]
kind = "latency"
port = "sins"
delay_s = 0.02
jitter_s = 0.01
start_s = 2.0
end_s = 2.5
[[faults]]
kind = "bandwidth"
port = "xbee"
bytes_per_s = 3000.0
start_s = 1.5
end_s = 2.0
[[faults]]
kind = "slicing"
port = "nanoloc"
probability = 0.5
start_s = 0.0
end_s = 3.0
[[faults]]
kind = "stuck"
port = "sins"
start_s = 2.6
end_s = 2.7
"""


def _run(sc, seed=4, record=None, duration_s=3.0):
    with Emulation(sc, seed, speed=None, ports=False, duration_s=duration_s,
                   record=record) as emu:
        summary = emu.run()
    return emu, summary


def test_every_kind_in_one_run_is_deterministic_and_its_recorded_ledger_matches(tmp_path):
    sc = variant(tmp_path, "office", EVERY_KIND, "every")
    a, summary = _run(sc, record=tmp_path / "a")
    b, _ = _run(sc)
    rec = Recording(tmp_path / "a")
    assert rec.faults() == b.ledger.entries  # the file holds what the run added
    kinds = {e["kind"] for e in b.ledger.entries}
    # every line kind, and the anchor outage on the reports it timed out
    assert kinds == {k for k in Fault.KINDS.built_in if Fault.KINDS.get(k).ACTS_ON == "line"} | {"anchor_outage"}
    assert {e["fault"] for e in b.ledger.entries} == set(range(0, 11))  # 0: the outage
    totals = {}
    for e in b.ledger.entries:
        t = totals.setdefault(e["kind"], {"injections": 0, "bytes": 0})
        t["injections"] += 1
        t["bytes"] += e["end"] - e["start"] + e.get("removed", 0)
    assert summary["faults"] == totals
    c, _ = _run(sc, record=tmp_path / "c")
    for port in PORTS:
        assert Recording(tmp_path / "c").read_bytes(port) == rec.read_bytes(port)
    for e in rec.faults():
        assert e["end"] <= rec.sizes[e["port"]]


def test_a_fault_on_one_port_leaves_the_others_and_the_ledger_explains_its_own(tmp_path):
    plain = variant(tmp_path, "office", "", "plain")
    _run(plain, record=tmp_path / "plain")
    clean = Recording(tmp_path / "plain")
    assert clean.faults() == [] and (tmp_path / "plain" / FAULTS).read_bytes() == b""
    for kind, settings in [("bit_errors", "ber = 0.002"), ("byte_drop", "probability = 0.01"),
                           ("byte_insert", "probability = 0.01"), ("garbage", "rate_hz = 4.0"),
                           ("stuck", "buffer_bytes = 50")]:
        sc = variant(tmp_path, "office", f'[[faults]]\nkind = "{kind}"\nport = "nanoloc"\n'
                                         f"{settings}\nstart_s = 1.0\nend_s = 2.0\n", kind)
        _run(sc, record=tmp_path / kind)
        rec = Recording(tmp_path / kind)
        for port in ("sins", "xbee"):
            assert rec.read_bytes(port) == clean.read_bytes(port), (kind, port)
        clean_bytes, faulted = clean.read_bytes("nanoloc"), rec.read_bytes("nanoloc")
        entries = rec.faults()
        assert entries and faulted != clean_bytes
        assert replay(clean_bytes, faulted, entries) == faulted, kind
        by_offset = {c.offset: c.t_device_ns for c in rec.chunks("nanoloc")}
        for e in entries:
            if kind != "garbage":  # a chunk's entries carry its device time
                start = max(o for o in by_offset if o <= e["start"])
                assert e["t_ns"] == by_offset[start], (kind, e)


class _MarkAll(LineWrapper):
    """Marks every chunk whole."""
    kind = "x"

    def send(self, start_ns, data, baud):
        self.mark(start_ns, 0, len(data))
        return start_ns, data


def test_an_entry_is_added_when_its_bytes_are_delivered_not_when_they_start():
    ledger = Ledger()
    line = Line("sins", Wire(BAUD), [_MarkAll()], ledger=ledger)
    line.put(0, b"ab")
    line.put(0, b"cd")
    assert line.poll(wire_ns(3, BAUD), SEC, SEC)[0].data == b"ab"  # "cd" is on the line
    assert [(e["start"], e["end"]) for e in ledger.entries] == [(0, 2)]
    line.poll(SEC, SEC, SEC)
    assert [(e["start"], e["end"]) for e in ledger.entries] == [(0, 2), (2, 4)]


def test_a_run_stopped_with_a_faulted_chunk_on_the_line_records_a_consistent_ledger(tmp_path):
    """The stop comes after the first block of virtual time, while an xbee chunk with bit
    errors is on the line: the complete recording neither has the chunk nor its entries
    (it failed with "entries past the end of xbee.bin", the lead's intermittent tutorial
    failure), and its ledger is the full run's over the bytes it has."""
    sc = variant(tmp_path, "office", "".join(
        f'[[faults]]\nkind = "bit_errors"\nport = "{p}"\nber = 0.05\n' for p in PORTS))
    stop = threading.Event()
    with Emulation(sc, 1, speed=None, ports=False, duration_s=5.0, record=tmp_path / "r",
                   sink=lambda chunk: stop.set()) as emu:
        summary = emu.run(stop)
        on_line = {p: line.current for p, line in emu.lines.items() if line.current}
    full, _ = _run(sc, seed=1, duration_s=5.0)
    rec = Recording(tmp_path / "r")
    assert rec.complete and summary["interrupted"] and summary["virtual_s"] < 5.0
    entries = rec.faults()
    assert any(rec.sizes[p] < e["end"] <= rec.sizes[p] + len(c.data)  # what this test is about
               for p, c in on_line.items() for e in full.ledger.entries if e["port"] == p)
    for port in PORTS:
        assert [e for e in entries if e["port"] == port] == \
            [e for e in full.ledger.entries if e["port"] == port and e["end"] <= rec.sizes[port]]
    assert summary["faults"]["bit_errors"]["injections"] == len(entries)


def test_the_ledger_reader_refuses_damage_and_skips_a_crash_tail(tmp_path):
    sc = variant(tmp_path, "office", '[[faults]]\nkind = "bit_errors"\nport = "sins"\n'
                                     "ber = 0.01\nstart_s = 0.0\nend_s = 1.0\n")
    _run(sc, record=tmp_path / "r", duration_s=1.0)
    path = tmp_path / "r" / FAULTS
    good = path.read_bytes()
    n = good.count(b"\n")
    assert len(Recording(tmp_path / "r").faults()) == n > 10
    entry = json.loads(good.splitlines()[0])
    for damage, words in [(b"{not json\n", "not a JSON object"), (b"[1]\n", "not an object"),
                          (json.dumps({**entry, "port": "gps"}).encode() + b"\n", "'gps'"),
                          (json.dumps({**entry, "start": 5, "end": 2}).encode() + b"\n",
                           "0 <= start <= end"),
                          (json.dumps({k: v for k, v in entry.items() if k != "t_ns"}).encode()
                           + b"\n", "lacks t_ns"),
                          (good[:-3], "partial last line")]:
        path.write_bytes(good + damage if damage != good[:-3] else damage)
        with pytest.raises(RecordingError, match=words):
            Recording(tmp_path / "r").faults()
    assert len(Recording(tmp_path / "r", salvage=True).faults()) == n - 1
    meta = tmp_path / "r" / "recording.json"
    meta.write_text(meta.read_text().replace('"complete": true', '"complete": false'))
    rec = Recording(tmp_path / "r")
    assert len(rec.faults()) == n - 1 and rec.skipped[FAULTS]["why"] == "a partial last line"
    path.unlink()  # a recording from before the ledger
    assert Recording(tmp_path / "r").faults() == []


# -- the command line ------------------------------------------------------------------------------
def test_fault_options_add_to_the_scenario_and_bad_ones_get_one_line(tmp_path):
    out = navtwin("emulate", "--scenario", "office", "--speed", "max", "--duration", "1",
                  "--quiet", "--link-dir", tmp_path / "l", "--record", tmp_path / "r",
                  "--fault", "byte_drop:port=sins,probability=0.01,start_s=0,end_s=5",
                  "--fault", "stuck:port=xbee,direction=to_device,start_s=0.5,end_s=0.6,repeat_s=0.2")
    assert out.returncode == 0, out.stderr
    done = json.loads(out.stdout.splitlines()[-1])
    rec = Recording(tmp_path / "r")
    drops = [e for e in rec.faults() if e["kind"] == "byte_drop"]
    assert done["faults"] == {"byte_drop": {"injections": len(drops),
                                            "bytes": sum(e["removed"] for e in drops)}}
    toml = (tmp_path / "r" / "scenario.toml").read_text()
    assert 'kind = "stuck"' in toml and 'direction = "to_device"' in toml
    for spec, words in [("byte_drop:port=gps,start_s=0,end_s=1", "port must be one of"),
                        ("latency:port=sins,start_s=0,end_s=1,delay=3", "did you mean 'delay_s'"),
                        ("slicing:port", "not key=value"),
                        ("bit_errors:port=sins,start_s=0,end_s=1,ber=2", "ber must be in (0, 1]")]:
        bad = navtwin("emulate", "--scenario", "office", "--link-dir", tmp_path / "l2",
                      "--fault", spec)
        assert bad.returncode == 2 and bad.stdout == ""
        (line,) = bad.stderr.strip().splitlines()
        assert "--fault" in line and words in line, line
