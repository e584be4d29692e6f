"""Streaming decoders: each error kind, resync, straddling, bounded memory."""
import random
import tracemalloc

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from navtwin.protocols import sins, xbee
from navtwin.protocols.stream import (BAD_CHECKSUM, BAD_CRC, BAD_ESCAPE, BAD_LENGTH, EVICTED, GARBAGE,
                              MALFORMED, MAX_SOURCES, TRUNCATED, DecodeError, Frame, XBeeDecoder,
                              XBeeSinsChain, nanoloc_decoder, sins_decoder)

from .strategies import FORMATS, chunked, garbage_bytes
from .test_properties import DECODERS
from .vectors import NANOLOC_5M, SINS_LEVEL, SINS_SEQ_WRAP, XBEE_API1

ROUTER = 0x0013A20040A1B2D4


def frames(events):
    return [e for e in events if isinstance(e, Frame)]


def kinds(events):
    return [e.kind for e in events if isinstance(e, DecodeError)]


def test_sins_errors_are_counted_and_frames_after_them_recovered():
    bad_crc = SINS_LEVEL[:-1] + b"\x00"
    bad_len = SINS_LEVEL[:3] + b"\x17" + SINS_LEVEL[4:]
    cut = SINS_LEVEL[:17]
    stream = b"junk" + bad_crc + SINS_LEVEL + bad_len + cut + SINS_SEQ_WRAP + SINS_LEVEL[:20]
    dec = sins_decoder()
    ev = dec.decode(stream)
    got = frames(ev)
    assert [f.fields["seq"] for f in got] == [1, 65535]
    assert [f.offset for f in got] == [4 + 30, 4 + 30 + 30 + 30 + 17]
    # the cut frame is caught by its CRC (bytes follow it); the one the stream ends in is truncated
    assert dec.errors[BAD_CRC] == 2 and dec.errors[BAD_LENGTH] == 1
    assert dec.errors[TRUNCATED] == 1
    assert dec.error_bytes[GARBAGE] == len(stream) - 60


def test_sins_unknown_type_is_skipped_by_len_and_kept_raw():
    from navtwin.protocols.crcframe import encode
    other = encode(sins.SYNC, 0x7F, b"\x01\x02\x03")
    (f1, f2) = frames(sins_decoder().decode(other + SINS_LEVEL))
    assert (f1.type, f1.known, f1.fields) == (0x7F, False, {"payload": b"\x01\x02\x03"})
    assert f2.fields["seq"] == 1


def test_nanoloc_in_one_byte_chunks():
    dec = nanoloc_decoder()
    ev = []
    for b in NANOLOC_5M * 3:
        ev += dec.feed(bytes([b]))
    ev += dec.flush()
    assert [f.offset for f in frames(ev)] == [0, 32, 64] and not kinds(ev)


@pytest.mark.parametrize("escaped", [False, True])
def test_xbee_error_kinds(escaped):
    good = xbee.wrap(XBEE_API1["receive_packet"][0][3:-1], escaped)
    bad_sum = good[:-1] + bytes([good[-1] ^ 1])
    zero_len = b"\x7e\x00\x00\x00"
    malformed = xbee.wrap(b"\x8b\x01\x02", escaped)  # a TX status must have 7 bytes
    stream = bad_sum + good + zero_len + malformed + good[:10]
    dec = XBeeDecoder(escaped=escaped)
    ev = dec.decode(stream)
    assert [f.offset for f in frames(ev)] == [len(bad_sum)]
    assert dec.errors[BAD_CHECKSUM] >= 1
    assert dec.errors[BAD_LENGTH] >= 1
    assert dec.errors[MALFORMED] == 1
    assert dec.errors[TRUNCATED] >= 1


def test_xbee_bad_escape_and_truncation_by_next_start():
    good = xbee.wrap(b"\x8a\x06", True)
    stream = b"\x7e\x00\x7d\x02\x8a" + good + b"\x7e\x00\x05\x88" + good
    dec = XBeeDecoder(escaped=True)
    ev = dec.decode(stream)
    assert [f.fields for f in frames(ev)] == [{"status": 6}, {"status": 6}]
    assert kinds(ev).count(BAD_ESCAPE) == 1 and kinds(ev).count(TRUNCATED) == 1


def test_xbee_escape_split_across_chunks():
    raw = xbee.build(0x90, escaped=True, src64=ROUTER, src16=0x7D84, options=1, data=b"\x7e\x7d\x11\x13")
    for cut in range(1, len(raw)):
        dec = XBeeDecoder(escaped=True)
        ev = dec.feed(raw[:cut]) + dec.feed(raw[cut:]) + dec.flush()
        (f,) = frames(ev)
        assert f.fields["data"] == b"\x7e\x7d\x11\x13" and not kinds(ev)


def test_unknown_xbee_type_kept_raw():
    raw = xbee.wrap(b"\xa1\x00\x13\xa2\x00", True)
    (f,) = frames(XBeeDecoder().decode(raw))
    assert (f.type, f.known, f.fields) == (0xA1, False, {"payload": b"\x00\x13\xa2\x00"})


def test_chain_rebuilds_sins_frames_straddling_packets():
    rng = random.Random(7)
    stream = b"".join(sins.build_sample(k, [rng.randrange(65536) for _ in range(11)])
                      for k in range(50))
    wire, pos = b"", 0
    while pos < len(stream):
        n = rng.randrange(1, 85)  # packets cut anywhere, at most NP = 84 bytes
        wire += xbee.build(0x90, src64=ROUTER, src16=0x1234, options=1, data=stream[pos:pos + n])
        pos += n
    wire += xbee.build(0x8A, status=6)
    chain = XBeeSinsChain()
    ev = []
    for k in range(0, len(wire), 13):
        ev += chain.feed(wire[k:k + 13])
    ev += chain.flush()
    sins_frames = [f for f in frames(ev) if f.format == "sins"]
    assert [f.fields["seq"] for f in sins_frames] == list(range(50))
    assert [f.offset for f in sins_frames] == [30 * k for k in range(50)]
    assert all(f.source == ROUTER for f in sins_frames)
    assert [f.type for f in frames(ev) if f.format == "xbee"] == [0x8A]
    assert not kinds(ev)


def test_chain_keeps_one_stream_per_source():
    a, b = sins.build_sample(1, [0] * 11), sins.build_sample(2, [0] * 11)
    wire = (xbee.build(0x90, src64=1, src16=1, options=1, data=a[:10])
            + xbee.build(0x90, src64=2, src16=2, options=1, data=b[:20])
            + xbee.build(0x90, src64=1, src16=1, options=1, data=a[10:])
            + xbee.build(0x90, src64=2, src16=2, options=1, data=b[20:]))
    got = frames(XBeeSinsChain().decode(wire))
    assert [(f.source, f.fields["seq"]) for f in got] == [(1, 1), (2, 2)]


def _rx(src64, data):
    """A 0x90 frame, built without construct (fast enough for 100,000 of them)."""
    return xbee.wrap(b"\x90" + src64.to_bytes(8, "big") + b"\xff\xfe\x01" + data, True)


def test_chain_evicts_the_least_recently_heard_source_and_says_so():
    a = sins.build_sample(1, [0] * 11)
    chain = XBeeSinsChain(max_sources=2)
    ev = chain.feed(_rx(1, a[:10]) + _rx(2, a[:5]) + _rx(1, a[10:]))  # 1 is now the most recent
    assert [(f.source, f.fields["seq"]) for f in frames(ev)] == [(1, 1)]
    ev = chain.feed(_rx(3, a))  # a third source: 2 goes, its 5 bytes reported as truncated
    errors = [(e.kind, e.source, e.offset, e.size) for e in ev if isinstance(e, DecodeError)]
    assert errors == [(TRUNCATED, 2, 0, 5), (GARBAGE, 2, 0, 5), (EVICTED, 2, 5, 5)]
    assert [(f.source, f.fields["seq"]) for f in frames(ev)] == [(3, 1)]
    assert list(chain.sins) == [1, 3] and chain.summary()["sources_evicted"] == 1
    ev = chain.feed(_rx(2, a))  # 2 again: a fresh stream, at offset 0; 1 goes (nothing held)
    assert [(f.source, f.offset) for f in frames(ev)] == [(2, 0)]
    assert [(e.kind, e.source, e.size) for e in ev if isinstance(e, DecodeError)] == \
        [(EVICTED, 1, 0)]


def test_chain_memory_is_bounded_whatever_the_number_of_sources():
    """Issue 7 point 9: 100,000 source addresses took one SINS decoder each (165 MB)."""
    half = sins.build_sample(1, [0] * 11)[:14]  # every stream holds a partial frame
    chain = XBeeSinsChain()

    def sources(lo, hi):  # the number of evictions they cause
        ev = []
        for k in range(lo, hi, 1000):
            ev += chain.feed(b"".join(_rx(0x0013A20000000000 + a, half)
                                      for a in range(k, k + 1000)))
        return sum(isinstance(e, DecodeError) and e.kind == EVICTED for e in ev)

    assert sources(0, 100_000) == chain.evicted == 100_000 - MAX_SOURCES
    assert len(chain.sins) == MAX_SOURCES == 64
    tracemalloc.start()  # 5,000 more (traced, so fewer): the memory stays where it was
    try:
        start = tracemalloc.get_traced_memory()[0]
        sources(100_000, 105_000)
        grown = tracemalloc.get_traced_memory()[0] - start
    finally:
        tracemalloc.stop()
    assert grown < 500_000  # bytes; one decoder per source would be about 4 MB


@pytest.mark.parametrize("make,limit", [
    (sins_decoder, 4 + 255 + 2),
    (nanoloc_decoder, 4 + 255 + 2),
    (lambda: XBeeDecoder(escaped=False), 1024 + 4),
    (lambda: XBeeDecoder(escaped=True), 2 * (1024 + 4)),
])
def test_memory_is_bounded_whatever_length_fields_claim(make, limit):
    rng = random.Random(3)
    dec = make()
    chunk = 256
    hostile = [b"\x7e\xff\xff", b"\x7e\x04\x00", b"\xa5\x5a\x7f\xff", b"\x4e\x4c\x7f\xff"]
    for _ in range(2000):
        piece = rng.choice(hostile) if rng.random() < 0.2 else rng.randbytes(chunk)
        dec.feed(piece)
        assert dec.buffered <= limit + chunk
    dec.flush()
    assert dec.buffered == 0


# -- chunking never changes the result: every event, sizes included -----------------------------

def _events(dec, chunks):
    out = []
    for c in chunks:
        out += dec.feed(c)
    out += dec.flush()
    return [(e.offset, e.raw, e.fields) if isinstance(e, Frame) else (e.kind, e.offset, e.size)
            for e in out]


@pytest.mark.parametrize("fmt", sorted(FORMATS))
@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_same_bytes_same_events_in_any_chunking(fmt, data):
    """Issue 7 point 9: in API mode 2 an error's size depended on where the input was cut."""
    parts = data.draw(st.lists(st.one_of(FORMATS[fmt], garbage_bytes), min_size=1, max_size=10))
    stream = b"".join(parts)
    whole = _events(DECODERS[fmt](), [stream])
    assert _events(DECODERS[fmt](), data.draw(chunked(stream))) == whole


def test_a_bad_escape_has_the_same_size_wherever_the_input_is_cut():
    """The issue's case: 47 bytes in one piece, 7 when cut at byte 109 (before the fix)."""
    f = xbee.build(0x90, True, src64=ROUTER, src16=0x1234, options=1, data=b"S" * 34)
    bad = b"\x7e\x00\x30\x41\x42\x7d\x00" + b"G" * 40  # 7D 00 is no escape
    stream = f + f + bad + f
    assert len(f + f) == 102
    for chunks in ([stream], [stream[:109], stream[109:]], [bytes([b]) for b in stream]):
        dec = XBeeDecoder(escaped=True)
        ev = _events(dec, chunks)
        assert ev[:2] == [(0, f, ev[0][2]), (51, f, ev[0][2])]
        assert ev[2:] == [(BAD_ESCAPE, 102, 7), (GARBAGE, 102, 47), (149, f, ev[0][2])]


#: Found by the xbee_sins fuzz target (tests/fuzz): golden packets, one of them (at 58) with
#: a bare 13 in its address; chunked, its bad_checksum was 46 bytes, whole 47.
FUZZ_BARE_XOFF = bytes.fromhex(
    "7e00028a00757e00028a066f7e002a900013a20040a1b2d4902601a55a011800008aa98010801280084100"
    "40137e4870038001800280005131727e002a900013a20040a1b2d490af2601a55a011800018aa9bff8bfff"
    "80bff6038022819e80018fff8001800082331d7e002a900013a20040a1b2d4902601a55a011800028aab80"
    "0cbfffbff8bff7800c818380008004c0018000ef8f837e002a900013a2004040a1b2d4902601a55a011800"
    "0a8aa9f7800c81838000efbffd812f80038ffe8fff800058117e00028a00757e00028a066f7e002a90007d"
    "33a20040a1617e00b2d4902601a55a011800008aa9801080128008bfffbfec81b78ffe8001800280005133"
    "726d6d6d6d6d6d6d6d6d6d6d6d6d6d6d6d")


def test_the_fuzzers_bare_xoff_input_keeps_its_contracts():
    from tests.fuzz import xbee_sins

    xbee_sins.check(FUZZ_BARE_XOFF)


def test_a_bare_xon_or_xoff_in_api_mode_2_does_not_swallow_the_next_frame():
    """A sender that leaves 11 and 13 unescaped: the frame's raw extent counted them as pairs,
    so with a byte of garbage after it the frame reached past the next 7E, and the intact
    frame there was lost (whole), or not (chunked)."""
    data = b"\x8a\x11\x13"
    bare = b"\x7e\x00\x03" + data + bytes((xbee.checksum(data),))
    good = xbee.build(0x8A, True, status=6)
    stream = bare + b"G" + good
    for chunks in ([stream], [stream[:7], stream[7:]]):
        assert _events(XBeeDecoder(escaped=True), chunks) == [
            (MALFORMED, 0, 7), (GARBAGE, 0, 8), (8, good, {"status": 6})]
