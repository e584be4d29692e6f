"""The SINS stream's wide sample frame (type 03, 32-bit ADIS16488A-class inertial words):
byte-exact vectors, the words' rounding and saturation, round trips through construct, the
fast builder and the streaming decoders, and its JSON and diff records."""
import binascii
import json
import math

import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario

from navtwin.protocols import adis16350, adis16488, sins, xbee
from navtwin.protocols.capture import Capture, write_recording
from navtwin.protocols.decode import decode, frame_record, printed, sins_labelled
from navtwin.protocols.diff import diff_bytes
from navtwin.protocols.fast import plain
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import Frame, XBeeSinsChain, sins_decoder

from ..helpers import navtwin

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


@pytest.fixture(scope="module")
def wide_run(tmp_path_factory):
    """2 s of rssi-centroid (words = "adis16488", magnetometer on) recorded, and its pcapng."""
    out = tmp_path_factory.mktemp("wide")
    with Emulation(load_scenario("rssi-centroid"), 3, speed=None, ports=False, duration_s=2.0,
                   record=out / "run") as emu:
        emu.run()
    with open(out / "run.pcapng", "wb") as f:
        write_recording(Recording(out / "run"), f)
    return out


def test_navtwin_decode_prints_the_board_line_and_the_radio_alike(wide_run):
    """Both ports' wide frames decode to the same records, whatever --gyro-range says (the
    frame's type says which words it carries)."""
    rows = {}
    for fmt, port, rng in (("sins", "sins", "300"), ("xbee-sins", "xbee", "75")):
        p = navtwin("decode", "--format", fmt, "--port", port, "--gyro-range", rng, str(wide_run / "run"))
        assert p.returncode == 0, p.stderr
        recs = [json.loads(x) for x in p.stdout.splitlines()]
        rows[port] = {r["seq"]: r for r in recs if r.get("type") == sins.TYPE_WIDE_SAMPLE}
        assert not [r for r in recs if r.get("type") == sins.TYPE_SAMPLE]
    assert len(rows["sins"]) == 200 and set(rows["xbee"]) <= set(rows["sins"]) and len(rows["xbee"]) >= 195
    for seq, r in rows["xbee"].items():
        a = rows["sins"][seq]
        assert {k: v for k, v in r.items() if k not in ("offset", "source", "format")} == \
               {k: v for k, v in a.items() if k not in ("offset", "format")}
    # driving straight north, level: the up gyro reads the earth's 15.04 sin(32 deg) =
    # 7.97 deg/h (1/8 of a 14-bit LSB at +-75 deg/s) within a deg/h over 2 s; z, gravity
    up = [r["gyro_dps"][2] * 3600 for r in rows["sins"].values()]
    assert sum(up) / len(up) == pytest.approx(15.041 * math.sin(math.radians(32)), abs=1.0)
    assert rows["sins"][100]["accel_m_s2"][2] == pytest.approx(9.7948, abs=0.002)


@needs_tshark
def test_wireshark_shows_the_emulated_wide_frames_on_both_ports(wide_run):
    expected = [r for r in decode(str(wide_run / "run"), "sins", port="sins")
                if r.get("type") == sins.TYPE_WIDE_SAMPLE]
    names = ["navtwin.sins.seq", "navtwin.sins.z_gyro", "navtwin.sins.zgyro_dps", "navtwin.sins.crc_ok"]
    for port in ("sins", "xbee"):  # the board's line, and the RF data of the 0x90 frames
        shown = []
        for row in fields(wide_run / "run.pcapng", *names,
                          where=f'frame.interface_name == "{port}" && navtwin.sins.type == 3'):
            shown += [list(f) for f in zip(*row)]
        by_seq = {r["seq"]: r for r in expected}
        assert len(shown) >= 195, port
        for seq, word, dps, ok in shown:
            e = by_seq[int(seq)]
            assert int(word) == e["gyro"][2] and float(dps) == pytest.approx(e["gyro_dps"][2], rel=1e-12)
            assert ok == "1"
