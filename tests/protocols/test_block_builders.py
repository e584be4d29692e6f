"""The block builders (a second's frames as the rows of one numpy array) equal the per-frame
builders and the construct declarations, byte for byte, on random and edge inputs: counters
at their wraps, every word and id at its limits, every status, the bytes the XBee's API mode
escapes (7E 7D 11 13) and the frames' syncs inside the fields; the column CRC equals the CRC
of each row; a value a field cannot hold is refused, as struct refuses it."""
import struct

import numpy as np
import pytest

from navtwin.protocols import nanoloc, sins, xbee
from navtwin.protocols.crc import RowsCrc, crc16, crc16_rows
from navtwin.protocols.fast import frames_of, packer_for, rows_packer
from navtwin.protocols.ieee802154 import fcs

#: bytes that mean something to a reader (API escapes, the syncs' bytes) and the limits
TRICKY_BYTES = [0x00, 0x11, 0x13, 0x4C, 0x4E, 0x5A, 0x7D, 0x7E, 0xA5, 0xFF]


def tricky(rng, shape, lo, hi):
    """Random values in [lo, hi], a third of them made of TRICKY_BYTES or at the limits."""
    width = max(1, (int(hi).bit_length() + 7) // 8)
    made = rng.choice(TRICKY_BYTES, (*shape, width)).astype(np.int64)
    words = (made << (8 * np.arange(width))).sum(axis=-1)
    words = lo + (words - lo) % (hi - lo + 1)
    random = rng.integers(lo, hi, shape, endpoint=True)
    edges = rng.choice([lo, hi, lo + 1, hi - 1], shape)
    pick = rng.integers(0, 3, shape)
    return np.choose(pick, [random, words, edges])


@pytest.mark.parametrize("length", [0, 1, 2, 9, 26, 28, 30, 55, 113])
@pytest.mark.parametrize("crc", [crc16, fcs], ids=["ccitt-false", "kermit"])
def test_the_column_crc_is_the_crc_of_each_row(crc, length):
    rng = np.random.default_rng(length)
    rows = rng.integers(0, 256, (64, length), dtype=np.uint8)
    rows[:8] = rng.choice(TRICKY_BYTES, (8, length))
    rows[8] = 0
    rows[9] = 0xFF
    assert RowsCrc(crc)(rows).tolist() == [crc(r.tobytes()) for r in rows]
    assert RowsCrc(crc)(rows[:0]).tolist() == []


def test_one_column_crc_serves_lengths_in_any_order():
    rows_crc, rng = RowsCrc(crc16), np.random.default_rng(7)
    for length in (30, 5, 41, 1, 30):
        rows = rng.integers(0, 256, (9, length), dtype=np.uint8)
        assert rows_crc(rows).tolist() == [crc16(r.tobytes()) for r in rows]


def test_one_bit_changes_the_column_crc():
    rows = np.zeros((1, 26), dtype=np.uint8)
    flipped = rows.copy()
    flipped[0, 13] ^= 0x10
    assert crc16_rows(rows)[0] != crc16_rows(flipped)[0]


@pytest.mark.parametrize("seed", range(3))
def test_sample_frames_equal_the_frame_builder_and_the_declaration(seed):
    rng = np.random.default_rng(seed)
    n = 300
    seq = np.concatenate(([0, 1, 65534, 65535, 65536, 65537, 131071, 10**9],
                          rng.integers(0, 1 << 20, n - 8)))
    words = tricky(rng, (n, 11), 0, 0xFFFF)
    block = sins.build_samples(seq, words)
    assert block.shape == (n, sins.FRAME_SIZE)
    frames = frames_of(block)
    assert frames == [sins.build_sample(s, w) for s, w in zip(seq.tolist(), words.tolist())]
    for s, w, f in list(zip(seq.tolist(), words.tolist(), frames))[:40]:
        assert f == sins.SinsFrame.build({"body": {"value": {
            "type": sins.TYPE_SAMPLE, "payload": {"seq": s % 65536, "words": w}}}})


@pytest.mark.parametrize("seed", range(3))
def test_wide_sample_frames_equal_the_frame_builder_and_the_declaration(seed):
    rng = np.random.default_rng(seed)
    n = 200
    seq = rng.integers(65500, 65600, n)
    words = np.empty((n, 11), dtype=np.int64)
    words[:, [0, 7, 8, 9, 10]] = tricky(rng, (n, 5), 0, 0xFFFF)
    words[:, 1:7] = tricky(rng, (n, 6), -(1 << 31), (1 << 31) - 1)
    frames = frames_of(sins.build_wide_samples(seq, words))
    expected = [sins.build_wide_sample(s, w[0], w[1:4], w[4:7], w[7:10], w[10])
                for s, w in zip(seq.tolist(), words.tolist())]
    assert frames == expected
    for s, w, f in list(zip(seq.tolist(), words.tolist(), frames))[:40]:
        assert f == sins.SinsFrame.build({"body": {"value": {
            "type": sins.TYPE_WIDE_SAMPLE, "payload": {
                "seq": s % 65536, "supply": w[0], "gyro": w[1:4], "accel": w[4:7],
                "temp": w[7:10], "aux": w[10]}}}})


@pytest.mark.parametrize("wide", [False, True])
@pytest.mark.parametrize("seed", range(3))
def test_reports_equal_the_report_builder_and_the_declaration(seed, wide):
    rng = np.random.default_rng(seed)
    n = 300
    ids = (1, 65534) if wide else nanoloc.NARROW_IDS
    fields = dict(
        seq=np.concatenate(([0, 65535, 65536, 70000], rng.integers(0, 1 << 17, n - 4))),
        t_us=np.concatenate(([0, (1 << 32) - 1, 1 << 32, (1 << 33) + 5],
                             rng.integers(0, 1 << 40, n - 4))),
        anchor=tricky(rng, (n,), *ids), tag=tricky(rng, (n,), *ids),
        status=rng.choice([0x0F, 0x40, 0x80, 0x00, 0x07, 0xCF, 0xFF], n),
        rssi=tricky(rng, (n,), -128, 127),
        tau=tricky(rng, (n, 4), 0, (1 << 32) - 1))
    block = nanoloc.build_reports(**fields, wide=wide)
    assert block.shape == (n, nanoloc.WIDE_FRAME_SIZE if wide else nanoloc.FRAME_SIZE)
    rows = [dict(zip(fields, values)) for values in zip(*(f.tolist() for f in fields.values()))]
    frames = frames_of(block)
    assert frames == [nanoloc.build_report(**r, wide=wide) for r in rows]
    ftype = nanoloc.TYPE_WIDE_RANGING if wide else nanoloc.TYPE_RANGING
    for r, f in list(zip(rows, frames))[:40]:
        payload = {**r, "seq": r["seq"] & 0xFFFF, "t_us": r["t_us"] & 0xFFFFFFFF}
        assert f == nanoloc.NanolocFrame.build({"body": {"value": {"type": ftype, "payload": payload}}})


def test_an_empty_block_has_no_frames():
    assert sins.build_samples(np.empty(0, dtype=np.int64), np.empty((0, 11), dtype=np.int64)).shape == (0, 30)
    assert frames_of(np.empty((0, 30), dtype=np.uint8)) == []


@pytest.mark.parametrize("column, value", [(0, -1), (0, 65536), (1, 65536)])
def test_a_value_the_field_cannot_hold_is_refused_as_struct_refuses_it(column, value):
    seq, words = np.array([5, 6]), np.full((2, 11), 7)
    (seq, words)[column][-1] = value if column == 0 else [value] * 11
    with pytest.raises(struct.error):
        packer_for(sins.Sample)(int(seq[-1]), *words[-1].tolist())
    with pytest.raises(ValueError, match="outside 0..65535"):
        rows_packer(sins.Sample)(seq, words)


def test_a_layout_without_a_row_form_is_refused():
    from construct import GreedyBytes, Int8ub, Struct

    with pytest.raises(TypeError, match="no row form"):
        rows_packer(Struct("a" / Int8ub, "rest" / GreedyBytes))


@pytest.mark.parametrize("escaped", [False, True], ids=["api1", "api2"])
@pytest.mark.parametrize("seed", range(4))
def test_many_xbee_frames_wrapped_at_once_equal_each_wrapped(seed, escaped):
    """xbee.wrap_many against xbee.wrap of each frame: data made of the escaped bytes,
    lengths whose bytes or checksum are themselves escaped (0x7D, 0x11, 0x13 ...), one byte."""
    rng = np.random.default_rng(seed)
    sizes = np.concatenate(([1, 0x11, 0x7D, 0x113, 0x7E7D], rng.integers(1, 120, 200)))
    rng.shuffle(sizes)
    frames = [rng.choice(TRICKY_BYTES, int(n)).astype(np.uint8).tobytes() for n in sizes]
    data, lengths = xbee.wrap_many(b"".join(frames), sizes, escaped)
    each = [xbee.wrap(f, escaped) for f in frames]
    assert data == b"".join(each) and lengths.tolist() == list(map(len, each))
    assert xbee.wrap_many(b"", [], escaped)[0] == b""
    with pytest.raises(ValueError, match="0 bytes"):
        xbee.wrap_many(b"a", [1, 0], escaped)
