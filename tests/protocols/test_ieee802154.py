"""The air's frames: IEEE 802.15.4 MAC, ZigBee NWK and APS headers, checked against the
spec's check value, their construct declarations and Wireshark's own dissectors."""
import io
import subprocess

import pytest

from navtwin.protocols import ieee802154, zigbee
from navtwin.protocols.capture import Capture
from navtwin.protocols.pcapng import LINKTYPE_IEEE802_15_4_WITHFCS

from ..tshark import tshark


PAN, ROUTER = 0x3A7C, 0x5B21


def test_fcs_is_crc16_kermit():
    assert ieee802154.fcs(b"123456789") == 0x2189


def test_fcs_residue_is_zero_over_a_psdu():
    psdu = ieee802154.data_frame(7, PAN, 0, ROUTER, b"payload")
    assert ieee802154.fcs(psdu) == 0
    assert ieee802154.fcs(psdu[:-1] + bytes((psdu[-1] ^ 1,))) != 0


def test_headers_are_the_radio_models_overhead():
    from navtwin.emulator.radio import RF_OVERHEAD_BYTES

    assert (ieee802154.PHY_HEADER_BYTES, ieee802154.MAC_HEADER_BYTES, zigbee.NWK_HEADER_BYTES,
            zigbee.APS_HEADER_BYTES, ieee802154.FCS_BYTES) == (6, 9, 8, 8, 2)
    assert RF_OVERHEAD_BYTES == zigbee.OVERHEAD_BYTES == 33
    assert ieee802154.ACK_NS == 544_000 and ieee802154.ACK_PSDU_BYTES == 5


def test_fast_builders_equal_the_declarations():
    payload = zigbee.data_packet(zigbee.COORDINATOR16, ROUTER, 0x1E, 300, 0x42, b"\x55\xaa")
    assert payload == zigbee.DataPacket.build(dict(
        nwk=dict(dst=0, src=ROUTER, radius=0x1E, seq=300 & 0xFF),
        aps=dict(dst_endpoint=0xE8, cluster=0x0011, profile=0xC105, src_endpoint=0xE8,
                 counter=0x42),
        data=b"\x55\xaa"))
    psdu = ieee802154.data_frame(0x101, PAN, 0, ROUTER, payload)
    assert psdu[:-2] == ieee802154.DataFrame.build(dict(
        header=dict(seq=0x01, dst_pan=PAN, dst=0, src=ROUTER), payload=payload))
    parsed = ieee802154.DataFrame.parse(psdu[:-2])
    assert (parsed.header.src, zigbee.DataPacket.parse(parsed.payload).data) == (ROUTER, b"\x55\xaa")
    assert ieee802154.ack_frame(0x101)[:-2] == ieee802154.AckHeader.build(dict(seq=1))
    # the frame control words as the specs' bit tables give them
    assert (ieee802154.DATA_FC, ieee802154.ACK_FC) == (b"\x61\x88", b"\x02\x00")
    assert (zigbee.NWK_FC, zigbee.APS_FC) == (b"\x48\x00", b"\x00")


FIELDS = ("frame.protocols wpan.frame_type wpan.ack_request wpan.pan_id_compression wpan.dst_pan "
          "wpan.src16 wpan.dst16 wpan.seq_no wpan.fcs_ok zbee_nwk.proto_version "
          "zbee_nwk.discovery zbee_nwk.src zbee_nwk.dst zbee_nwk.radius zbee_nwk.seqno "
          "zbee_aps.type zbee_aps.delivery zbee_aps.dst zbee_aps.src zbee_aps.cluster "
          "zbee_aps.profile zbee_aps.counter data.data").split()


def dissect(frames, tmp_path) -> list[dict]:
    """Wireshark's dissection of *frames* (PSDUs), one dict of FIELDS per frame."""
    out = io.BytesIO()
    capture = Capture(out, {})
    air = capture.interface("air", LINKTYPE_IEEE802_15_4_WITHFCS, "the XBee hop")
    for i, psdu in enumerate(frames):
        capture.writer.packet(air, 1_000_000 * i, psdu)
    path = tmp_path / "air.pcapng"
    path.write_bytes(out.getvalue())
    args = [tshark(), "-r", str(path), "-T", "fields", "-E", "occurrence=l"]
    for f in FIELDS:
        args += ["-e", f]
    text = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    return [dict(zip(FIELDS, line.split("\t"))) for line in text.splitlines()]


def test_wiresharks_dissectors_read_the_data_frame_and_its_ack(tmp_path):
    data = bytes(range(30))
    psdu = ieee802154.data_frame(0xC8, PAN, zigbee.COORDINATOR16, ROUTER,
                                 zigbee.data_packet(zigbee.COORDINATOR16, ROUTER, 0x1E, 0x17,
                                                    0x2A, data))
    frame, ack = dissect([psdu, ieee802154.ack_frame(0xC8)], tmp_path)
    assert frame["frame.protocols"].startswith("wpan:zbee_nwk:zbee_aps")
    assert frame | {"frame.protocols": ""} == {
        "frame.protocols": "", "wpan.frame_type": "0x0001", "wpan.ack_request": "1",
        "wpan.pan_id_compression": "1", "wpan.dst_pan": "0x3a7c", "wpan.src16": "0x5b21",
        "wpan.dst16": "0x0000", "wpan.seq_no": "200", "wpan.fcs_ok": "1",
        "zbee_nwk.proto_version": "2", "zbee_nwk.discovery": "0x0001", "zbee_nwk.src": "0x5b21",
        "zbee_nwk.dst": "0x0000", "zbee_nwk.radius": "30", "zbee_nwk.seqno": "23",
        "zbee_aps.type": "0x00", "zbee_aps.delivery": "0x00", "zbee_aps.dst": "232",
        "zbee_aps.src": "232", "zbee_aps.cluster": "0x0011", "zbee_aps.profile": "0xc105",
        "zbee_aps.counter": "42", "data.data": data.hex()}
    assert (ack["frame.protocols"], ack["wpan.frame_type"], ack["wpan.seq_no"],
            ack["wpan.fcs_ok"]) == ("wpan", "0x0002", "200", "1")


def test_a_corrupted_frame_fails_wiresharks_fcs_check(tmp_path):
    psdu = bytearray(ieee802154.data_frame(1, PAN, 0, ROUTER, zigbee.data_packet(
        0, ROUTER, 0x1E, 1, 1, b"x")))
    psdu[12] ^= 0x01
    (frame,) = dissect([bytes(psdu)], tmp_path)
    assert frame["wpan.fcs_ok"] == "0"


def test_the_documented_vector():
    """docs/protocols.md section 4."""
    psdu = ieee802154.data_frame(5, 0x3A7C, 0, 0x5B21, zigbee.data_packet(
        0, 0x5B21, 0x1E, 5, 5, bytes.fromhex("A55A0118")))
    assert psdu.hex(" ").upper() == ("61 88 05 7C 3A 00 00 21 5B 48 00 00 00 21 5B 1E 05 00 E8 "
                                     "11 00 05 C1 E8 05 A5 5A 01 18 47 05")
    assert ieee802154.ack_frame(5).hex(" ").upper() == "02 00 05 15 E2"


def test_the_fcs_is_crc16_kermit_bit_by_bit():
    """fcs() against the CRC's definition, a bit at a time (reflected 0x1021, init 0)."""
    import random

    from navtwin.protocols.ieee802154 import fcs

    def bitwise(data: bytes) -> int:
        crc = 0
        for byte in data:
            crc ^= byte
            for _ in range(8):
                crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
        return crc

    rng = random.Random(5)
    for n in range(130):
        data = bytes(rng.randrange(256) for _ in range(n))
        assert fcs(data) == bitwise(data)
    assert fcs(b"123456789") == 0x2189
