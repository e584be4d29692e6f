"""The SINS stream's magnetometer frame (type 02): byte-exact vectors, round trips through
construct, the fast builder and the streaming decoders, and its JSON record."""
import binascii

import pytest

from navtwin.protocols import sins, xbee
from navtwin.protocols.decode import frame_record, printed
from navtwin.protocols.fast import plain
from navtwin.protocols.stream import Frame, XBeeSinsChain, sins_decoder

# seq 10; x +230, y -50, z -480 LSB (21.10, -4.59, -44.04 uT: a level vehicle heading east
# of north at 34 deg N); the CRC from binascii's CRC-CCITT (init 0xFFFF), an independent code
MAG_LEVEL = bytes.fromhex("A55A0208000A00E6FFCEFE207172")
# seq 65535; x overflow (-4096), y +2047, z -2048 (the HMC5883L's extremes)
MAG_EXTREMES = bytes.fromhex("A55A0208FFFFF00007FFF800B2E8")


@pytest.mark.parametrize("frame, seq, words", [(MAG_LEVEL, 10, (230, -50, -480)),
                                               (MAG_EXTREMES, 65535, (-4096, 2047, -2048))])
def test_vectors_byte_exact(frame, seq, words):
    assert binascii.crc_hqx(frame[2:-2], 0xFFFF) == int.from_bytes(frame[-2:], "big")
    assert sins.build_magnetometer(seq, words) == frame
    parsed = sins.SinsFrame.parse(frame)
    assert parsed.body.value.type == sins.TYPE_MAGNETOMETER
    assert plain(parsed.body.value.payload) == {"seq": seq, "field": words}
    assert sins.SinsFrame.build(parsed) == frame
    assert len(frame) == sins.MAG_FRAME_SIZE


def test_decoded_between_samples_with_engineering_units():
    a, b = sins.build_sample(10, [0x8000] * 11), sins.build_sample(11, [0x8000] * 11)
    events = sins_decoder().decode(a + MAG_LEVEL + b)
    assert [type(e) for e in events] == [Frame] * 3
    assert [e.type for e in events] == [1, 2, 1]
    rec = printed(frame_record(events[1]))
    assert rec["seq"] == 10 and rec["field_words"] == [230, -50, -480]
    assert rec["field_ut"] == pytest.approx([230 / 10.9, -50 / 10.9, -480 / 10.9], abs=1e-4)
    assert frame_record(sins_decoder().decode(MAG_EXTREMES)[0])["field_ut"] is None  # overflow


def test_carried_by_the_xbee_chain_across_packets():
    stream = sins.build_sample(10, [0x8000] * 11) + MAG_LEVEL
    packets = [stream[:35], stream[35:]]  # the magnetometer frame straddles two 0x90 packets
    data = b"".join(xbee.build(xbee.FrameType.RECEIVE_PACKET, True, src64=0x0013A20040A1B2D4,
                               src16=0x1234, options=1, data=p) for p in packets)
    frames = [e for e in XBeeSinsChain().decode(data) if e.format == "sins"]
    assert [(f.type, f.fields["seq"]) for f in frames] == [(1, 10), (2, 10)]
    assert frames[1].fields["field"] == (230, -50, -480)


@pytest.mark.parametrize("bad", [MAG_LEVEL[:3] + b"\x09" + MAG_LEVEL[4:],  # a wrong length
                                 MAG_LEVEL[:-1] + b"\x00"])  # a wrong CRC
def test_a_damaged_frame_is_an_error_not_a_frame(bad):
    events = sins_decoder().decode(bad)
    assert not any(isinstance(e, Frame) for e in events)
