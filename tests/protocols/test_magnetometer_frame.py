"""The SINS stream's magnetometer frame (type 02): byte-exact vectors, round trips through
construct, the fast builder and the streaming decoders, and its JSON record."""
import binascii
import dataclasses

import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import Magnetometer, load_scenario
from navtwin.protocols.capture import write_recording
from navtwin.protocols.decode import decode
from navtwin.protocols.recording import Recording

from navtwin.protocols import sins, xbee
from navtwin.protocols.decode import frame_record, printed
from navtwin.protocols.diff import diff_bytes
from navtwin.protocols.fast import plain
from navtwin.protocols.stream import Frame, XBeeSinsChain, sins_decoder

from ..tshark import fields, needs_tshark

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


def test_diff_pairs_a_magnetometer_frame_with_its_own_type_and_names_its_axes():
    sample = sins.build_sample(10, [0x8000] * 11)
    other = sins.build_magnetometer(10, (230, -49, -480))
    # B lost the sample frame: its magnetometer frame (same seq) must not pair with A's sample
    d = diff_bytes(sample + MAG_LEVEL, other, "sins")
    p = d.ports["sins"]
    [c] = p.changed.items
    [f] = c.fields
    assert (f.name, f.a, f.b) == ("YMAG", 0xFFCE, 0xFFCF)
    assert f.text() == "YMAG 0xFFCE -> 0xFFCF (+0.0917431 uT)"
    assert [r.key for r in p.only_a.items] == [10] and p.only_a.items[0].type == sins.TYPE_SAMPLE


@needs_tshark
def test_wireshark_shows_the_magnetometer_frames_navtwin_decode_gives(tmp_path):
    sc = load_scenario("office")
    sc = dataclasses.replace(sc, magnetometer=Magnetometer(enabled=True, hard_iron_ut=(1.0, 2.0, 3.0)))
    with Emulation(sc, 4, speed=None, ports=False, duration_s=2.0, record=tmp_path / "run") as emu:
        emu.run()
    with open(tmp_path / "run.pcapng", "wb") as f:
        write_recording(Recording(tmp_path / "run"), f)
    names = ["navtwin.sins.seq", "navtwin.sins.xmag", "navtwin.sins.ymag", "navtwin.sins.zmag",
             "navtwin.sins.xmag_ut", "navtwin.sins.ymag_ut", "navtwin.sins.zmag_ut",
             "navtwin.sins.crc_ok"]
    expected = [[r["seq"], *r["field_words"], *r["field_ut"], True]
                for r in decode(str(tmp_path / "run"), "sins", port="sins") if r.get("type") == 2]
    assert len(expected) == 20
    for port in ("sins", "xbee"):  # the board's line, and the RF data of the 0x90 frames
        shown = []
        for row in fields(tmp_path / "run.pcapng", *names,
                          where=f'frame.interface_name == "{port}" && navtwin.sins.type == 2'):
            shown += [list(f) for f in zip(*row)]
        assert len(shown) == len(expected), port
        for s, e in zip(shown, expected):
            assert [int(v, 0) for v in s[:4]] == e[:4]
            assert [float(v) for v in s[4:7]] == pytest.approx(e[4:7], rel=1e-12)
            assert s[7] == "1"
