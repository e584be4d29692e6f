"""The SINS stream's wide sample frame (type 03, 32-bit ADIS16488A-class inertial words):
byte-exact vectors, the words' rounding and saturation, round trips through construct, the
fast builder and the streaming decoders, and its JSON and diff records."""
import binascii

import pytest

from navtwin.protocols import adis16350, adis16488, sins, xbee
from navtwin.protocols.capture import Capture
from navtwin.protocols.decode import frame_record, printed, sins_labelled
from navtwin.protocols.diff import diff_bytes
from navtwin.protocols.fast import plain
from navtwin.protocols.stream import Frame, XBeeSinsChain, sins_decoder

from ..tshark import fields, needs_tshark

# seq 1, supply 5.0 V (2730 = 0xAAA, ND); gyro x 0, y +0.01 deg/s (half an _OUT LSB: 0x8000
# in the _LOW word), z -1 LSB; accel 0, 0, +1 g (1250 _OUT LSBs: 0x04E2 << 16); temperatures
# 25 degC and AUX 0 with ND. The CRC from binascii's CRC-CCITT (init 0xFFFF), an independent code.
WIDE_LEVEL = bytes.fromhex("A55A0324" "0001" "8AAA" "00000000" "00008000" "FFFFFFFF"
                           "00000000" "00000000" "04E20000" "800080008000" "8000" "B8FA")
LEVEL_FIELDS = {"seq": 1, "supply": 0x8AAA, "gyro": (0, 32768, -1), "accel": (0, 0, 81920000),
                "temp": (0x8000,) * 3, "aux": 0x8000}
# seq 65535; gyro +450, -450 deg/s (22500 << 16) and saturated; accel +18, -18 g and saturated
# low; housekeeping words with EA and without ND
WIDE_EXTREMES = bytes.fromhex("A55A0324" "FFFF" "4AAA" "57E40000" "A81C0000" "7FFFFFFF"
                              "57E40000" "A81C0000" "80000000" "400040004000" "4000" "5A46")


@pytest.mark.parametrize("frame", [WIDE_LEVEL, WIDE_EXTREMES])
def test_vectors_byte_exact(frame):
    assert len(frame) == sins.WIDE_FRAME_SIZE == 42
    assert binascii.crc_hqx(frame[2:-2], 0xFFFF) == int.from_bytes(frame[-2:], "big")
    parsed = sins.SinsFrame.parse(frame)
    assert parsed.body.value.type == sins.TYPE_WIDE_SAMPLE
    assert sins.SinsFrame.build(parsed) == frame
    f = plain(parsed.body.value.payload)
    assert sins.build_wide_sample(f["seq"], f["supply"], f["gyro"], f["accel"], f["temp"], f["aux"]) == frame


def test_the_level_vector_from_physical_values():
    fields = adis16488.from_sample(gyro_dps=(0.0, 0.01, -0.5 * adis16488.GYRO_LSB_DPS - 1e-12),
                                   accel_g=(0.0, 0.0, 1.0))
    assert {"seq": 1, **fields} == LEVEL_FIELDS
    assert sins.build_wide_sample(1, **fields) == WIDE_LEVEL
    assert plain(sins.SinsFrame.parse(WIDE_LEVEL).body.value.payload) == LEVEL_FIELDS


def test_the_extremes_saturate():
    fields = adis16488.from_sample(gyro_dps=(450.0, -450.0, 1e6), accel_g=(18.0, -18.0, -1e6),
                                   nd=False, ea=True)
    assert sins.build_wide_sample(65535, **fields) == WIDE_EXTREMES


def test_rounding_is_half_away_from_zero_and_saturates():
    lsb = adis16488.GYRO_LSB_DPS
    assert [adis16488.counts(k * lsb, lsb) for k in (0.5, 1.5, -0.5, -1.5, 0.49, -0.49)] == [1, 2, -1, -2, 0, 0]
    import numpy as np
    x = np.array([0.5, 1.5, -0.5, -1.5, 0.49, 1e12, -1e12]) * lsb
    assert adis16488.counts(x, lsb).tolist() == [1, 2, -1, -2, 0, adis16488.WORD_MAX, adis16488.WORD_MIN]
    assert adis16488.counts(1e12, lsb) == adis16488.WORD_MAX and adis16488.counts(-1e12, lsb) == adis16488.WORD_MIN


def test_engineering_units_carry_the_fine_words():
    """0.04 deg/h, 003's drift, is 36 counts of the wide words; in the ADIS16350's words at
    +-75 deg/s it rounds to 0."""
    rate = 0.04 / 3600  # deg/s
    wide = adis16488.from_sample(gyro_dps=(rate, 0, 0), accel_g=(100e-6, 0, 1))
    s = sins.to_sample(sins.TYPE_WIDE_SAMPLE, wide, 300)
    assert s.gyro_dps[0] == pytest.approx(rate, abs=adis16488.GYRO_LSB_DPS / 2)
    assert s.accel_g[0] == pytest.approx(100e-6, abs=adis16488.ACCEL_LSB_G / 2)
    assert s.temp_c == (25.0, 25.0, 25.0) and s.supply_v == pytest.approx(5.0, abs=1e-3)
    assert all(s.nd) and not s.ea
    narrow = adis16350.sample_to_words(gyro_dps=(rate, 0, 0), accel_g=(100e-6, 0, 1), gyro_range=75)
    assert adis16350.words_to_sample(narrow, 75).gyro_dps[0] == 0.0


def test_decoded_in_the_stream_with_engineering_units():
    mag = sins.build_magnetometer(1, (230, -50, -480))
    events = sins_decoder().decode(WIDE_LEVEL + mag + WIDE_EXTREMES)
    assert [(type(e), e.type) for e in events] == [(Frame, 3), (Frame, 2), (Frame, 3)]
    rec = printed(frame_record(events[0]))
    assert rec["seq"] == 1 and rec["gyro"] == [0, 32768, -1] and rec["accel"] == [0, 0, 81920000]
    assert rec["gyro_dps"] == pytest.approx([0.0, 0.01, -adis16488.GYRO_LSB_DPS], abs=1e-9)
    assert rec["gyro_dps"][2] != 0.0  # printed to the wide words' resolution, not the ADIS16350's
    assert rec["accel_g"] == [0.0, 0.0, 1.0] and rec["nd"] and not rec["ea"]
    ext = frame_record(events[2])
    assert ext["gyro_dps"][:2] == [450.0, -450.0] and ext["accel_g"][:2] == [18.0, -18.0]
    assert ext["ea"] and not ext["nd"]


def test_labelled_for_diff_names_each_register_pair():
    labelled = sins_labelled(sins_decoder().decode(WIDE_LEVEL)[0], 300)
    assert list(labelled) == ["seq", "SUPPLY_OUT", *adis16488.WORDS, "XTEMP_OUT", "YTEMP_OUT",
                              "ZTEMP_OUT", "AUX_ADC"]
    assert labelled["Z_GYRO"] == (0xFFFFFFFF, -adis16488.GYRO_LSB_DPS, "deg/s")
    assert labelled["Z_ACCL"] == (81920000, 1.0, "g")


def test_carried_by_the_xbee_chain_across_packets():
    packets = [WIDE_LEVEL[:25], WIDE_LEVEL[25:]]  # the frame straddles two 0x90 packets
    data = b"".join(xbee.build(xbee.FrameType.RECEIVE_PACKET, True, src64=0x0013A20040A1B2D4,
                               src16=0x1234, options=1, data=p) for p in packets)
    frames = [e for e in XBeeSinsChain().decode(data) if e.format == "sins"]
    assert [(f.type, f.fields["seq"], f.fields["accel"]) for f in frames] == [(3, 1, (0, 0, 81920000))]


@pytest.mark.parametrize("bad", [WIDE_LEVEL[:3] + b"\x1e" + WIDE_LEVEL[4:],  # type 01's length
                                 WIDE_LEVEL[:-1] + b"\x00"])  # a wrong CRC
def test_a_damaged_frame_is_an_error_not_a_frame(bad):
    assert not any(isinstance(e, Frame) for e in sins_decoder().decode(bad))


@needs_tshark
def test_wireshark_shows_the_wide_words_navtwin_decode_gives(tmp_path):
    with open(tmp_path / "wide.pcapng", "wb") as f:
        cap = Capture(f, {})
        cap.chunk("sins", 10_000_000, WIDE_LEVEL + sins.build_magnetometer(1, (1, 2, 3)))
        cap.chunk("sins", 20_000_000, WIDE_EXTREMES)
        cap.flush()
    names = ["navtwin.sins.seq", *(f"navtwin.sins.{w.lower()}" for w in adis16488.WORDS),
             "navtwin.sins.xgyro_dps", "navtwin.sins.ygyro_dps", "navtwin.sins.zgyro_dps",
             "navtwin.sins.xaccl_g", "navtwin.sins.yaccl_g", "navtwin.sins.zaccl_g",
             "navtwin.sins.supply_v", "navtwin.sins.xtemp_c", "navtwin.sins.nd", "navtwin.sins.ea",
             "navtwin.sins.crc_ok"]
    rows = fields(tmp_path / "wide.pcapng", *names, where="navtwin.sins.type == 3")
    shown = [[v[0] for v in row] for row in rows]
    expected = [frame_record(e) for e in sins_decoder().decode(WIDE_LEVEL + WIDE_EXTREMES)]
    assert len(shown) == len(expected) == 2
    for s, e in zip(shown, expected):
        assert [int(v) for v in s[:7]] == [e["seq"], *e["gyro"], *e["accel"]]
        assert [float(v) for v in s[7:13]] == pytest.approx(e["gyro_dps"] + e["accel_g"], rel=1e-12, abs=1e-15)
        assert float(s[13]) == pytest.approx(e["supply_v"]) and float(s[14]) == pytest.approx(e["temp_c"][0])
        assert [s[15], s[16], s[17]] == [str(int(e["nd"])), str(int(e["ea"])), "1"]


def test_diff_names_the_changed_32_bit_word_and_its_change_in_units():
    other = bytearray(WIDE_LEVEL)
    other[15] = 0x01  # Y_GYRO's lowest byte: 0x00008000 -> 0x00008001, one LSB
    other[-2:] = binascii.crc_hqx(bytes(other[2:-2]), 0xFFFF).to_bytes(2, "big")
    [c] = diff_bytes(WIDE_LEVEL, bytes(other), "sins").ports["sins"].changed.items
    [f] = c.fields
    assert (f.name, f.a, f.b) == ("Y_GYRO", 0x8000, 0x8001)
    assert f.text() == "Y_GYRO 0x8000 -> 0x8001 (+3.05176e-07 deg/s)"
