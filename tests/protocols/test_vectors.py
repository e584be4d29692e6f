"""The normative vectors decode and re-encode byte-exact, through construct and the decoders."""
import math

import pytest

from navtwin.protocols import adis16350 as adis
from navtwin.protocols import nanoloc, sins, xbee
from navtwin.protocols.crc import crc16
from navtwin.protocols.fast import plain
from navtwin.protocols.stream import XBeeDecoder, nanoloc_decoder, sins_decoder

from .vectors import NANOLOC_5M, SINS_LEVEL, SINS_SEQ_WRAP, XBEE_API1, XBEE_API2


def test_crc_check_value():
    assert crc16(b"123456789") == 0x29B1


def test_sins_level_vector():
    f = sins.SinsFrame.parse(SINS_LEVEL)
    p = f.body.value.payload
    assert p.seq == 1
    s = adis.words_to_sample(p.words)
    assert s.supply_v == pytest.approx(5.0, abs=1e-3)
    assert s.gyro_dps == (0.0, 0.0, 0.0)
    assert s.accel_g[:2] == (0.0, 0.0)
    assert s.accel_m_s2[2] == pytest.approx(9.7952, abs=adis.ACCEL_LSB_G * adis.STANDARD_GRAVITY)
    assert s.temp_c == (25.0, 25.0, 25.0)
    assert all(s.nd) and not s.ea
    assert sins.SinsFrame.build(f) == SINS_LEVEL
    words = adis.sample_to_words(gyro_dps=(0, 0, 0), accel_g=(0, 0, 9.7952 / adis.STANDARD_GRAVITY))
    assert sins.build_sample(1, words) == SINS_LEVEL


def test_sins_wrap_vector():
    p = sins.SinsFrame.parse(SINS_SEQ_WRAP).body.value.payload
    assert p.seq == 65535
    w = p.words
    assert [adis.signed(w[i], 14) for i in (1, 3, 5, 6)] == [1092, -1092, -397, 396]
    assert adis.signed(w[7], 12) == -69
    assert sins.build_sample(65535, w) == SINS_SEQ_WRAP
    assert sins.build_sample(65536 + 65535, w) == SINS_SEQ_WRAP  # the counter wraps


def test_adis_datasheet_coding():
    # Tables 7 and 8: +80 deg/s at +-300 is 0x0444, -80 is 0x3BBC, -1 LSB 0x3FFF; 1 g = 0x018D
    assert adis.pack(adis.quantise(80.0, adis.GYRO_LSB_DPS[300]), 14, nd=False) == 0x0444
    assert adis.pack(adis.quantise(-80.0, adis.GYRO_LSB_DPS[300]), 14, nd=False) == 0x3BBC
    assert adis.pack(-1, 14, nd=False) == 0x3FFF
    assert adis.pack(adis.quantise(1.0, adis.ACCEL_LSB_G), 14, nd=False) == 0x018D
    assert adis.pack(adis.quantise(2.522, adis.ACCEL_LSB_G), 14, nd=False) == 0x03E8
    # saturation at the end of the 14-bit range, flags kept
    assert adis.pack(10**6, 14) == 0x8000 | 0x1FFF
    assert adis.pack(-10**6, 14, ea=True) == 0xC000 | 0x2000
    assert adis.gyro_range_from_sens_avg(0x0402) == 300
    assert adis.gyro_range_from_sens_avg(0x0204) == 150
    with pytest.raises(ValueError):
        adis.gyro_range_from_sens_avg(0x0602)


@pytest.mark.parametrize("rng", [300, 150, 75])
def test_adis_units_round_trip(rng):
    words = adis.sample_to_words(gyro_dps=(12.3, -45.6, 0.7), accel_g=(0.5, -1.25, 0.98),
                                 temp_c=(30.0, 20.0, 25.0), supply_v=4.9, aux_v=1.2, gyro_range=rng)
    s = adis.words_to_sample(words, rng)
    lsb = adis.GYRO_LSB_DPS[rng]
    for got, want in zip(s.gyro_dps, (12.3, -45.6, 0.7)):  # inside every range's digital span
        assert abs(got - want) <= lsb / 2 + 1e-12
    sat = adis.words_to_sample(adis.sample_to_words(gyro_dps=(1e4, -1e4, 0), accel_g=(0, 0, 0),
                                                    gyro_range=rng), rng)
    assert sat.gyro_dps[:2] == (8191 * lsb, -8192 * lsb)  # saturates at the 14-bit ends
    assert all(abs(g - w) <= adis.ACCEL_LSB_G / 2 for g, w in zip(s.accel_g, (0.5, -1.25, 0.98)))
    assert s.supply_v == pytest.approx(4.9, abs=adis.SUPPLY_LSB_V)
    assert s.aux_v == pytest.approx(1.2, abs=adis.AUX_LSB_V)
    assert s.gyro_rad_s[0] == pytest.approx(math.radians(s.gyro_dps[0]))


def test_nanoloc_vector():
    p = nanoloc.NanolocFrame.parse(NANOLOC_5M).body.value.payload
    assert (p.seq, p.t_us, p.anchor, p.tag, p.status, p.rssi) == (7, 1234567, 1, 0x10, 0x0F, -62)
    assert nanoloc.distance(*p.tau) == pytest.approx(4.99994, abs=1e-5)
    assert nanoloc.NanolocFrame.build(nanoloc.NanolocFrame.parse(NANOLOC_5M)) == NANOLOC_5M
    assert nanoloc.build_report(seq=7, t_us=1234567, anchor=1, tag=0x10, status=0x0F, rssi=-62,
                                tau=list(p.tau)) == NANOLOC_5M


@pytest.mark.parametrize("name", sorted(XBEE_API1))
def test_xbee_api1_examples(name):
    raw, ftype, fields = XBEE_API1[name]
    parsed = xbee.ApiFrame.parse(raw)
    assert parsed.frame.value.type == ftype
    body = plain(parsed.frame.value.body)
    assert {k: body[k] for k in fields} == fields
    assert xbee.ApiFrame.build(parsed) == raw
    assert xbee.wrap(raw[3:-1], escaped=False) == raw
    # the streaming decoder agrees
    (frame,) = XBeeDecoder(escaped=False).decode(raw)
    assert (frame.type, frame.raw, frame.offset) == (ftype, raw, 0)
    assert {k: frame.fields[k] for k in fields} == fields
    # and the same frame in API mode 2
    esc = xbee.wrap(raw[3:-1], escaped=True)
    assert xbee.ApiFrameEscaped.build(xbee.ApiFrameEscaped.parse(esc)) == esc
    (frame2,) = XBeeDecoder(escaped=True).decode(esc)
    assert frame2.fields == frame.fields and frame2.raw == esc


@pytest.mark.parametrize("name", sorted(XBEE_API2))
def test_xbee_api2_examples(name):
    escaped, plain_frame = XBEE_API2[name]
    assert xbee.wrap(plain_frame[3:-1], escaped=True) == escaped
    assert xbee.unescape(escaped[1:]) == plain_frame[1:]
    (frame,) = XBeeDecoder(escaped=True).decode(escaped)
    assert frame.raw == escaped


def test_build_by_fields_matches_digi_example():
    raw = XBEE_API1["transmit_request"][0]
    assert xbee.build(0x10, escaped=False, frame_id=1, dest64=0x0013A200400A0127, dest16=0xFFFE,
                      radius=0, options=0, data=b"TxData0A") == raw


def test_decoders_on_vectors():
    (f,) = sins_decoder().decode(SINS_LEVEL)
    assert f.fields == {"seq": 1, "words": tuple(sins.SinsFrame.parse(SINS_LEVEL).body.value.payload.words)}
    (n,) = nanoloc_decoder().decode(NANOLOC_5M)
    assert n.fields["tau"] == (100033356, 100000000, 100033356, 100000000)
