"""The nanoLOC gateway's wide ranging report (type 02, 16-bit anchor and tag ids): a
byte-exact vector through construct and the fast builder, round trips, a mixed stream with
garbage, a type-01-only reader skipping it by len, its decode record and Wireshark's view."""
import binascii

import pytest

from navtwin.protocols import nanoloc
from navtwin.protocols.capture import Capture
from navtwin.protocols.decode import frame_record
from navtwin.protocols.fast import plain
from navtwin.protocols.stream import CrcFramedDecoder, Frame, nanoloc_decoder

from ..tshark import fields, needs_tshark
from .vectors import NANOLOC_5M

TAU_5M = [100033356, 100000000, 100033356, 100000000]  # NANOLOC_5M's taus: 4.99994 m
# NANOLOC_5M's exchange from anchor 1001 (03E9) of a grid field, tag 0x0010, in a type 02
# report; the CRC from binascii's CRC-CCITT (init 0xFFFF), an independent code
WIDE_5M = bytes.fromhex("4E4C" "021C" "0007" "0012D687" "03E9" "0010" "0F" "C2"
                        "05F6634C" "05F5E100" "05F6634C" "05F5E100" "470E")
WIDE_FIELDS = {"seq": 7, "t_us": 1234567, "anchor": 1001, "tag": 0x10, "status": 0x0F, "rssi": -62,
               "tau": tuple(TAU_5M)}


def test_vector_byte_exact_through_construct_and_the_fast_path():
    assert len(WIDE_5M) == nanoloc.WIDE_FRAME_SIZE == 34
    assert binascii.crc_hqx(WIDE_5M[2:-2], 0xFFFF) == int.from_bytes(WIDE_5M[-2:], "big")
    built = nanoloc.NanolocFrame.build({"body": {"value": {"type": nanoloc.TYPE_WIDE_RANGING,
                                                           "payload": WIDE_FIELDS}}})
    fast = nanoloc.build_report(**WIDE_FIELDS, wide=True)
    assert built == fast == WIDE_5M


def test_round_trip():
    parsed = nanoloc.NanolocFrame.parse(WIDE_5M)
    assert parsed.body.value.type == nanoloc.TYPE_WIDE_RANGING
    assert plain(parsed.body.value.payload) == WIDE_FIELDS
    assert nanoloc.NanolocFrame.build(parsed) == WIDE_5M
    assert nanoloc.distance(*parsed.body.value.payload.tau) == pytest.approx(4.99994, abs=1e-5)
    top = nanoloc.build_report(**{**WIDE_FIELDS, "anchor": 65534, "tag": 65534}, wide=True)
    assert plain(nanoloc.NanolocFrame.parse(top).body.value.payload)["anchor"] == 65534


def test_a_narrow_report_is_unchanged_by_the_wide_parameter():
    assert nanoloc.build_report(**{**WIDE_FIELDS, "anchor": 1}, wide=False) == NANOLOC_5M


def test_mixed_stream_with_garbage_decodes_every_frame():
    data = b"\x4e\x00garbage" + WIDE_5M + NANOLOC_5M + b"\x4e\x4c\x02" + WIDE_5M[:-1] + b"\x00" + WIDE_5M
    events = nanoloc_decoder().decode(data)
    frames = [e for e in events if isinstance(e, Frame)]
    assert [(f.type, f.fields["anchor"]) for f in frames] == [(2, 1001), (1, 1), (2, 1001)]
    assert all(f.known for f in frames)
    assert [f.offset for f in frames] == [9, 43, 75 + 3 + 34]
    assert [f.raw for f in frames] == [WIDE_5M, NANOLOC_5M, WIDE_5M]


def test_a_reader_of_type_01_only_skips_it_by_len():
    old = CrcFramedDecoder("nanoloc", nanoloc.SYNC, {nanoloc.TYPE_RANGING: nanoloc.Ranging})
    frames = [e for e in old.decode(WIDE_5M + NANOLOC_5M) if isinstance(e, Frame)]
    assert [(f.type, f.known) for f in frames] == [(2, False), (1, True)]
    assert frames[1].fields["anchor"] == 1


@pytest.mark.parametrize("bad", [WIDE_5M[:3] + b"\x1a" + WIDE_5M[4:],  # type 01's length
                                 WIDE_5M[:-1] + b"\x00"])  # a wrong CRC
def test_a_damaged_report_is_an_error_not_a_frame(bad):
    assert not any(isinstance(e, Frame) for e in nanoloc_decoder().decode(bad))


def test_decode_record_gives_the_wide_ids_and_the_distance():
    rec = frame_record(nanoloc_decoder().decode(WIDE_5M)[0])
    assert (rec["type"], rec["anchor"], rec["tag"], rec["seq"]) == (2, 1001, 0x10, 7)
    assert rec["complete"] and rec["distance_m"] == pytest.approx(4.99994, abs=1e-5)


@needs_tshark
def test_wireshark_shows_the_wide_ids(tmp_path):
    with open(tmp_path / "wide.pcapng", "wb") as f:
        cap = Capture(f, {})
        cap.chunk("nanoloc", 10_000_000, WIDE_5M + NANOLOC_5M)
        cap.flush()
    rows = fields(tmp_path / "wide.pcapng", "navtwin.nanoloc.type", "navtwin.nanoloc.anchor",
                  "navtwin.nanoloc.tag", "navtwin.nanoloc.distance_m", "navtwin.nanoloc.crc_ok")
    [row] = rows
    assert [int(v, 0) for v in row[0]] == [2, 1]
    assert [int(v) for v in row[1]] == [1001, 1]
    assert [float(v) for v in row[3]] == pytest.approx([4.99994] * 2, abs=1e-5)
    assert row[4] == ["1", "1"]
