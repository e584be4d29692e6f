"""Cross-checks with two independent XBee implementations: digi-xbee 1.5.0 and python-xbee 2.3.2.

Frames built by each library parse identically with ours (through the streaming decoder, in
API mode 1 and 2), and frames we build parse in both, field for field.
"""
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navtwin.protocols import xbee
from navtwin.protocols.bench import digi_frames, pyxbee_frames
from navtwin.protocols.stream import Frame, XBeeDecoder

pytest.importorskip("digi.xbee")
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress  # noqa: E402
from digi.xbee.models.status import (ATCommandStatus, DiscoveryStatus, ModemStatus,  # noqa: E402
                                     TransmitStatus)
from digi.xbee.packets import common as dp  # noqa: E402

pyxbee = pytest.importorskip("xbee")
from xbee.frame import APIFrame  # noqa: E402

u8, u16, u64 = st.integers(0, 255), st.integers(0, 0xFFFF), st.integers(0, 2**64 - 1)
data = st.binary(max_size=84)
cmd = st.sampled_from([b"VR", b"HV", b"SH", b"SL", b"DB", b"AP", b"BD", b"MY", b"NI", b"AI"])
at_status = st.sampled_from([0, 1, 2, 3, 4])
tx_status = st.sampled_from([0x00, 0x01, 0x02, 0x21, 0x22, 0x23, 0x24, 0x25, 0x74])
discovery = st.sampled_from([0x00, 0x01, 0x02, 0x03, 0x40])
modem = st.sampled_from([0x00, 0x01, 0x02, 0x03, 0x06])

# frame type -> strategy of our field dicts
FIELDS = {
    0x08: st.fixed_dictionaries({"frame_id": u8, "command": cmd, "parameter": st.binary(max_size=4)}),
    0x09: st.fixed_dictionaries({"frame_id": u8, "command": cmd, "parameter": st.binary(max_size=4)}),
    0x88: st.fixed_dictionaries({"frame_id": u8, "command": cmd, "status": at_status,
                                 "value": st.binary(max_size=8)}),
    0x8A: st.fixed_dictionaries({"status": modem}),
    0x8B: st.fixed_dictionaries({"frame_id": u8, "dest16": u16, "retries": u8, "delivery": tx_status,
                                 "discovery": discovery}),
    0x10: st.fixed_dictionaries({"frame_id": u8, "dest64": u64, "dest16": u16, "radius": u8,
                                 "options": u8, "data": data}),
    0x11: st.fixed_dictionaries({"frame_id": u8, "dest64": u64, "dest16": u16, "src_endpoint": u8,
                                 "dest_endpoint": u8, "cluster": u16, "profile": u16, "radius": u8,
                                 "options": u8, "data": data}),
    0x17: st.fixed_dictionaries({"frame_id": u8, "dest64": u64, "dest16": u16, "options": u8,
                                 "command": cmd, "parameter": st.binary(max_size=4)}),
    0x90: st.fixed_dictionaries({"src64": u64, "src16": u16, "options": u8, "data": data}),
    0x91: st.fixed_dictionaries({"src64": u64, "src16": u16, "src_endpoint": u8, "dest_endpoint": u8,
                                 "cluster": u16, "profile": u16, "options": u8, "data": data}),
    0x97: st.fixed_dictionaries({"frame_id": u8, "src64": u64, "src16": u16, "command": cmd,
                                 "status": at_status, "value": st.binary(max_size=8)}),
}


def a64(v):
    return XBee64BitAddress(v.to_bytes(8, "big"))


def a16(v):
    return XBee16BitAddress(v.to_bytes(2, "big"))


def opt(b):
    return bytearray(b) if b else None


def digi_packet(t, f):
    """digi-xbee's packet class for our fields."""
    c = f.get("command", b"").decode()
    return {
        0x08: lambda: dp.ATCommPacket(f["frame_id"], c, opt(f["parameter"])),
        0x09: lambda: dp.ATCommQueuePacket(f["frame_id"], c, opt(f["parameter"])),
        0x88: lambda: dp.ATCommResponsePacket(f["frame_id"], c, ATCommandStatus.get(f["status"]),
                                              opt(f["value"])),
        0x8A: lambda: dp.ModemStatusPacket(ModemStatus.get(f["status"])),
        0x8B: lambda: dp.TransmitStatusPacket(f["frame_id"], a16(f["dest16"]), f["retries"],
                                              TransmitStatus.get(f["delivery"]),
                                              DiscoveryStatus.get(f["discovery"])),
        0x10: lambda: dp.TransmitPacket(f["frame_id"], a64(f["dest64"]), a16(f["dest16"]), f["radius"],
                                        f["options"], opt(f["data"])),
        0x11: lambda: dp.ExplicitAddressingPacket(f["frame_id"], a64(f["dest64"]), a16(f["dest16"]),
                                                  f["src_endpoint"], f["dest_endpoint"], f["cluster"],
                                                  f["profile"], f["radius"], f["options"],
                                                  opt(f["data"])),
        0x17: lambda: dp.RemoteATCommandPacket(f["frame_id"], a64(f["dest64"]), a16(f["dest16"]),
                                               f["options"], c, opt(f["parameter"])),
        0x90: lambda: dp.ReceivePacket(a64(f["src64"]), a16(f["src16"]), f["options"], opt(f["data"])),
        0x91: lambda: dp.ExplicitRXIndicatorPacket(a64(f["src64"]), a16(f["src16"]), f["src_endpoint"],
                                                   f["dest_endpoint"], f["cluster"], f["profile"],
                                                   f["options"], opt(f["data"])),
        0x97: lambda: dp.RemoteATCommandResponsePacket(f["frame_id"], a64(f["src64"]), a16(f["src16"]),
                                                       c, ATCommandStatus.get(f["status"]),
                                                       opt(f["value"])),
    }[t]()


def ours(raw, escaped):
    (frame,) = [e for e in XBeeDecoder(escaped).decode(raw)]
    assert isinstance(frame, Frame)
    return frame


@pytest.mark.parametrize("ftype", sorted(FIELDS), ids=hex)
@pytest.mark.parametrize("escaped", [False, True], ids=["api1", "api2"])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_digi_xbee_agrees(ftype, escaped, data):
    fields = data.draw(FIELDS[ftype])
    pkt = digi_packet(ftype, fields)
    theirs = bytes(pkt.output(escaped=escaped))
    mine = xbee.build(ftype, escaped=escaped, **fields)
    assert theirs == mine  # they build what we build
    frame = ours(theirs, escaped)  # we parse what they build
    assert (frame.type, frame.fields) == (ftype, fields)
    (back,) = digi_frames(mine, escaped)  # they read what we build, through their own read path
    assert back.get_frame_type_value() == ftype
    assert bytes(back.output(escaped=escaped)) == mine


def _pyxbee_fields(ftype, f):
    """python-xbee's response dict for our fields (its field names, bytes values)."""
    b8 = lambda v: v.to_bytes(8, "big")  # noqa: E731
    b2 = lambda v: v.to_bytes(2, "big")  # noqa: E731
    b1 = lambda v: bytes([v])  # noqa: E731
    return {
        0x88: lambda: {"id": "at_response", "frame_id": b1(f["frame_id"]), "command": f["command"],
                       "status": b1(f["status"]), **({"parameter": f["value"]} if f["value"] else {})},
        0x8A: lambda: {"id": "status", "status": b1(f["status"])},
        0x8B: lambda: {"id": "tx_status", "frame_id": b1(f["frame_id"]), "dest_addr": b2(f["dest16"]),
                       "retries": b1(f["retries"]), "deliver_status": b1(f["delivery"]),
                       "discover_status": b1(f["discovery"])},
        0x90: lambda: {"id": "rx", "source_addr_long": b8(f["src64"]), "source_addr": b2(f["src16"]),
                       "options": b1(f["options"]), **({"rf_data": f["data"]} if f["data"] else {})},
        0x91: lambda: {"id": "rx_explicit", "source_addr_long": b8(f["src64"]),
                       "source_addr": b2(f["src16"]), "source_endpoint": b1(f["src_endpoint"]),
                       "dest_endpoint": b1(f["dest_endpoint"]), "cluster": b2(f["cluster"]),
                       "profile": b2(f["profile"]), "options": b1(f["options"]),
                       **({"rf_data": f["data"]} if f["data"] else {})},
        0x97: lambda: {"id": "remote_at_response", "frame_id": b1(f["frame_id"]),
                       "source_addr_long": b8(f["src64"]), "source_addr": b2(f["src16"]),
                       "command": f["command"], "status": b1(f["status"]),
                       **({"parameter": f["value"]} if f["value"] else {})},
    }[ftype]()


@pytest.mark.parametrize("ftype", [0x88, 0x8A, 0x8B, 0x90, 0x91, 0x97], ids=hex)
@pytest.mark.parametrize("escaped", [False, True], ids=["api1", "api2"])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_python_xbee_parses_what_we_build(ftype, escaped, data):
    fields = data.draw(FIELDS[ftype])
    raw = xbee.build(ftype, escaped=escaped, **fields)
    (got,) = pyxbee_frames(raw, escaped)  # python-xbee's own read loop and parser
    assert got == _pyxbee_fields(ftype, fields)


COMMANDS = {  # python-xbee command name -> (our type, their kwargs from our fields)
    "at": (0x08, lambda f: {"frame_id": bytes([f["frame_id"]]), "command": f["command"],
                            "parameter": f["parameter"]}),
    "queued_at": (0x09, lambda f: {"frame_id": bytes([f["frame_id"]]), "command": f["command"],
                                   "parameter": f["parameter"]}),
    "tx": (0x10, lambda f: {"frame_id": bytes([f["frame_id"]]), "dest_addr_long": f["dest64"].to_bytes(8, "big"),
                            "dest_addr": f["dest16"].to_bytes(2, "big"),
                            "broadcast_radius": bytes([f["radius"]]), "options": bytes([f["options"]]),
                            "data": f["data"]}),
    "tx_explicit": (0x11, lambda f: {"frame_id": bytes([f["frame_id"]]),
                                     "dest_addr_long": f["dest64"].to_bytes(8, "big"),
                                     "dest_addr": f["dest16"].to_bytes(2, "big"),
                                     "src_endpoint": bytes([f["src_endpoint"]]),
                                     "dest_endpoint": bytes([f["dest_endpoint"]]),
                                     "cluster": f["cluster"].to_bytes(2, "big"),
                                     "profile": f["profile"].to_bytes(2, "big"),
                                     "broadcast_radius": bytes([f["radius"]]),
                                     "options": bytes([f["options"]]), "data": f["data"]}),
    "remote_at": (0x17, lambda f: {"frame_id": bytes([f["frame_id"]]),
                                   "dest_addr_long": f["dest64"].to_bytes(8, "big"),
                                   "dest_addr": f["dest16"].to_bytes(2, "big"),
                                   "options": bytes([f["options"]]), "command": f["command"],
                                   "parameter": f["parameter"]}),
}


@pytest.mark.parametrize("name", sorted(COMMANDS))
@pytest.mark.parametrize("escaped", [False, True], ids=["api1", "api2"])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_we_parse_what_python_xbee_builds(name, escaped, data):
    ftype, kwargs = COMMANDS[name]
    fields = data.draw(FIELDS[ftype])
    zb = pyxbee.ZigBee(None, escaped=escaped)
    raw = APIFrame(zb._build_command(name, **kwargs(fields)), escaped).output()
    assert raw == xbee.build(ftype, escaped=escaped, **fields)
    frame = ours(raw, escaped)
    assert (frame.type, frame.fields) == (ftype, fields)


def test_node_identification_python_xbee():
    """0x95 (digi-xbee has no ZB class for it): python-xbee parses our build of Digi's example."""
    fields = {"src64": 0x0013A20040522BAA, "src16": 0x7D84, "options": 2, "remote16": 0x7D84,
              "remote64": 0x0013A20040522BAA, "ni": "SINS-ROUTER", "parent16": 0xFFFE,
              "device_type": 1, "source_event": 1, "profile": 0xC105, "manufacturer": 0x101E,
              "device_type_id": None}
    raw = xbee.build(0x95, escaped=True, **fields)
    (got,) = pyxbee_frames(raw, True)
    assert got["node_id"] == b"SINS-ROUTER" and got["device_type"] == b"\x01"
    assert got["manufacturer_id"] == b"\x10\x1e"
    assert ours(raw, True).fields == fields
