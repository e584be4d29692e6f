"""protocols.diff: two recordings (or byte streams) compared frame by frame."""
import json

import pytest

from navtwin.protocols import adis16350, sins
from navtwin.protocols.diff import DiffError, diff_bytes, diff_recordings
from navtwin.protocols.recording import RecordingError

from .. import recorded

FRAME = sins.FRAME_SIZE
ZGYRO = adis16350.REGISTERS.index("ZGYRO_OUT")
WORDS_AT = 6  # byte offset of the first register word in a SINS frame


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return recorded.compared_runs(tmp_path_factory.mktemp("runs"))


def test_same_seed_is_equal(runs):
    d = diff_recordings(runs["one"], runs["again"])
    assert d.equal
    assert list(d.ports) == ["sins", "xbee", "nanoloc"]
    sins_port = d.ports["sins"]
    assert sins_port.first is None and sins_port.frames_a == sins_port.frames_b == 200
    assert d.text().endswith("equal\n")
    assert json.loads(json.dumps(d.to_json()))["equal"] is True


def test_two_seeds_name_the_first_differing_frame_and_field(runs):
    d = diff_recordings(runs["one"], runs["two"], max_shown=3)
    assert not d.equal
    p = d.ports["sins"]
    a, b = (runs[n] / "sins.bin" for n in ("one", "two"))
    first = next(i for i, (x, y) in enumerate(zip(a.read_bytes(), b.read_bytes())) if x != y)
    assert p.first.offset == first and p.first.frame.key == first // FRAME  # seq n: byte 30 n
    assert p.first.t_device_ns == 1_000_000  # the first frame's chunk, from sins.csv
    assert p.changed.count == 200 and len(p.changed.items) == 3
    c = p.changed.items[0]
    assert c.a.key == c.b.key == 0
    words_a = [int.from_bytes(a.read_bytes()[WORDS_AT + 2 * i:WORDS_AT + 2 * i + 2], "big")
               for i in range(11)]
    z = next(f for f in c.fields if f.name == "ZGYRO_OUT")
    assert z.a == words_a[ZGYRO] and z.unit == "deg/s"
    lsb = adis16350.GYRO_LSB_DPS[300]
    assert z.b_value - z.a_value == pytest.approx(
        (adis16350._s14(z.b) - adis16350._s14(z.a)) * lsb)
    assert f"ZGYRO_OUT 0x{z.a:04X} -> 0x{z.b:04X} (" in d.text()
    assert "... and 197 more changed frames" in d.text()
    assert p.only_a.count == p.only_b.count == 0


def test_one_flipped_bit_is_that_frame(runs, tmp_path):
    """A flipped bit breaks the frame's CRC: the frame is only in A, B has a bad_crc where it
    was, and nothing else differs."""
    b = recorded.copy(runs["one"], tmp_path / "flip")
    at = 7 * FRAME + WORDS_AT + 2 * ZGYRO + 1  # seq 7's ZGYRO_OUT, low byte
    recorded.flip_bit(b, "sins", at, bit=2)
    d = diff_recordings(runs["one"], b)
    assert not d.equal and d.ports["xbee"].equal and d.ports["nanoloc"].equal
    p = d.ports["sins"]
    assert (p.first.offset, p.first.frame.key, p.first.frame.by_seq) == (at, 7, True)
    assert p.first.t_device_ns == 71_000_000
    assert [r.key for r in p.only_a.items] == [7] and p.only_a.items[0].offset == 7 * FRAME
    assert p.changed.count == 0 and p.only_b.count == 0 and p.errors_a.count == 0
    assert {(e["error"], e["offset"], e["size"]) for e in p.errors_b.items} == {
        ("bad_crc", 7 * FRAME, FRAME), ("garbage", 7 * FRAME, FRAME)}
    assert "only in A: seq 7 at byte 210" in d.text()


def test_a_flipped_bit_with_its_crc_mended_is_a_changed_field():
    frame = sins.build_sample(1234, [0x8000 | 0x0123] * 11)
    words = [0x8000 | 0x0123] * 11
    words[ZGYRO] += 1
    other = sins.build_sample(1234, words)
    d = diff_bytes(frame * 2, frame + other, "sins")
    p = d.ports["sins"]
    assert p.first.offset == FRAME + WORDS_AT + 2 * ZGYRO + 1
    [c] = p.changed.items
    [f] = c.fields
    assert (f.name, f.a, f.b) == ("ZGYRO_OUT", 0x8123, 0x8124)
    assert f.text() == "ZGYRO_OUT 0x8123 -> 0x8124 (+0.07326 deg/s)"
    assert "seq 1234: ZGYRO_OUT 0x8123 -> 0x8124 (+0.07326 deg/s)" in d.text()


def test_a_frame_cut_out_is_only_in_a(runs, tmp_path):
    b = recorded.copy(runs["one"], tmp_path / "cut")
    recorded.cut_chunk(b, "sins", 42)  # the board writes one frame a chunk
    p = diff_recordings(runs["one"], b, ports=["sins"]).ports["sins"]
    assert [r.key for r in p.only_a.items] == [42] and p.only_a.count == 1
    assert p.changed.count == 0 and p.only_b.count == 0  # the rest do not shift
    assert p.errors_a.count == p.errors_b.count == 0 and p.timing.count == 0
    assert p.first.offset == 42 * FRAME + 5  # seq 42 -> 43: the low byte of the seq


def test_timing_beyond_the_tolerance(runs, tmp_path):
    b = recorded.copy(runs["one"], tmp_path / "late")
    index = b / "sins.csv"
    lines = index.read_text().splitlines()
    off, size, dev, wall = lines[11].split(",")  # seq 10
    lines[11] = f"{off},{size},{int(dev) + 2_000_000},{wall}"
    lines[12:] = [f"{o},{s},{int(t) + 2_000_000},{w}" for o, s, t, w in
                  (x.split(",") for x in lines[12:])]
    index.write_text("\n".join(lines) + "\n")
    p = diff_recordings(runs["one"], b, ports=["sins"]).ports["sins"]
    assert p.first is None and not p.equal and p.timing.count == 190
    assert p.timing.items[0].a.key == 10 and p.timing.items[0].delta_ns == 2_000_000
    assert diff_recordings(runs["one"], b, ports=["sins"], time_tolerance_s=0.002).equal


def test_frames_without_seq_align_by_position(runs):
    """XBee API frames carry no seq: the n-th frame of A pairs with the n-th of B."""
    p = diff_recordings(runs["one"], runs["two"], ports=["xbee"]).ports["xbee"]
    assert not any(c.a.by_seq or c.b.by_seq for c in p.changed.items)
    assert all(c.a.key == c.b.key for c in p.changed.items)
    assert "data" in {f.name for f in p.changed.items[0].fields}


def test_bad_inputs(runs, tmp_path):
    with pytest.raises(RecordingError, match="no recording.json"):
        diff_recordings(runs["one"], tmp_path)
    with pytest.raises(DiffError, match=r"^port: nope in neither recording"):
        diff_recordings(runs["one"], runs["two"], ports=["nope"])


def test_the_sins_stream_inside_xbee_packets_names_the_register(runs):
    """xbee-sins: the chain's frames are SINS frames, so their words are named as on the
    board's own port."""
    a, b = ((runs[n] / "xbee.bin").read_bytes() for n in ("one", "two"))
    p = diff_bytes(a, b, "xbee-sins").ports["xbee-sins"]
    assert p.changed.count == 200 and p.changed.items[0].a.by_seq
    assert "ZGYRO_OUT" in {f.name for f in p.changed.items[0].fields}
