"""Captures (issue 19 item 5): the pcapng writer and a recording written as a capture, read
back by tshark with navtwin's Lua dissectors and checked against navtwin decode's records."""
from __future__ import annotations

import io
import math
import random
import re

import pytest

from navtwin.protocols import adis16350, nanoloc, sins, xbee
from navtwin.protocols.capture import (LINKTYPES, UNDISSECTED, CaptureError,
                                       dissectors_path, write_recording)
from navtwin.protocols.decode import decode
from navtwin.protocols.pcapng import INBOUND, LINKTYPE_USER0, OUTBOUND, Writer
from navtwin.protocols.recording import Recording, RecordingWriter

from .. import recorded
from ..tshark import fields, packets


def test_the_lua_file_registers_the_link_types_capture_declares():
    """The numbers are written once in capture.LINKTYPES; the Lua file names the same
    wtap encapsulations (USERn is link type 147 + n)."""
    lua = dissectors_path().read_text()
    table = re.search(r"local LINKTYPES = \{(.*?)\}", lua, re.S)[1]
    declared = {name: LINKTYPE_USER0 + int(n)
                for name, n in re.findall(r"(\w+) = wtap\.USER(\d+)", table)}
    assert declared == {fmt + ("_escaped" if escaped else ""): linktype
                        for (fmt, escaped), linktype in LINKTYPES.items()}
    for name in declared:
        assert f"encap:add(LINKTYPES.{name}," in lua


def test_tshark_reads_the_writers_interfaces_times_directions_and_comments(tmp_path):
    path = tmp_path / "w.pcapng"
    with open(path, "wb") as f:
        w = Writer(f)
        a = w.interface("alpha", UNDISSECTED, "first")
        b = w.interface("beta", UNDISSECTED)
        w.packet(a, 1_234_567_891_234_567_891, b"\x01\x02\x03", direction=INBOUND,
                 comment="t_wall_ns=5")
        w.packet(b, 7, b"\xff" * 5, direction=OUTBOUND)
        w.packet(a, 1_000_000_000, b"x")
    rows = packets(path)
    assert [(r["interface"], r["time"], r["direction"], r["comment"], r["data"]) for r in rows] == [
        ("alpha", "1234567891.234567891", INBOUND, "t_wall_ns=5", b"\x01\x02\x03"),
        ("beta", "0.000000007", OUTBOUND, None, b"\xff" * 5),
        ("alpha", "1.000000000", 0, None, b"x")]


@pytest.fixture(scope="module")
def office(tmp_path_factory):
    """A 2 s office run and its capture."""
    base = tmp_path_factory.mktemp("capture")
    rec = recorded.office(base / "run", 5)
    with open(base / "run.pcapng", "wb") as f:
        written = write_recording(Recording(rec), f)
    return rec, base / "run.pcapng", written


def _ns(t: str) -> int:
    s, ns = t.split(".")
    return int(s) * 10**9 + int(ns)


def test_each_port_is_an_interface_with_its_chunks_byte_for_byte(office):
    rec, capture, written = office
    recording = Recording(rec)
    rows = packets(capture)
    assert written.clock == "device"
    for port in recording.ports:
        chunks = list(recording.chunks(port))
        mine = [r for r in rows if r["interface"] == port]
        assert [r["data"] for r in mine] == [c.data for c in chunks]
        assert [_ns(r["time"]) for r in mine] == [c.t_device_ns for c in chunks]
        assert {r["direction"] for r in mine} == {INBOUND}
        assert written.packets[port] == len(chunks)
        assert written.bytes[port] == recording.sizes[port]
    times = [_ns(r["time"]) for r in rows]
    assert times == sorted(times)  # one time order across the ports


def _records(rec, fmt: str, port: str) -> list[dict]:
    return [r for r in decode(str(rec), fmt, port=port) if "type" in r]


SINS_FIELDS = ["navtwin.sins.seq", *(f"navtwin.sins.{n.lower()}" for n in adis16350.REGISTERS),
               "navtwin.sins.supply_v", "navtwin.sins.xgyro_dps", "navtwin.sins.ygyro_dps",
               "navtwin.sins.zgyro_dps", "navtwin.sins.xaccl_g", "navtwin.sins.yaccl_g",
               "navtwin.sins.zaccl_g", "navtwin.sins.xtemp_c", "navtwin.sins.ytemp_c",
               "navtwin.sins.ztemp_c", "navtwin.sins.aux_v", "navtwin.sins.nd",
               "navtwin.sins.ea", "navtwin.sins.crc_ok"]


def _sins_frames(capture, where: str) -> list[list[str]]:
    """Every SINS frame tshark shows on the packets *where* selects: its SINS_FIELDS."""
    frames = []
    for row in fields(capture, *SINS_FIELDS, where=where):
        frames += [list(f) for f in zip(*row)]  # each field occurs once per frame
    return frames


def _expected_sins(r: dict) -> list:
    return [r["seq"], *r["words"], r["supply_v"], *r["gyro_dps"], *r["accel_g"],
            *r["temp_c"], r["aux_v"], r["nd"], r["ea"], True]


def _same(shown: list[str], expected: list) -> bool:
    for s, e in zip(shown, expected, strict=True):
        if isinstance(e, bool):
            ok = s == str(int(e))
        elif isinstance(e, float):
            ok = math.isclose(float(s), e, rel_tol=1e-12, abs_tol=1e-12)
        else:
            ok = int(s, 0) == e
        if not ok:
            return False
    return True


def test_every_sins_frame_shows_the_fields_navtwin_decode_gives(office):
    rec, capture, _ = office
    shown = _sins_frames(capture, 'frame.interface_name == "sins"')
    expected = [_expected_sins(r) for r in _records(rec, "sins", "sins")]
    assert len(shown) == len(expected) == 200
    bad = [(s, e) for s, e in zip(shown, expected) if not _same(s, e)]
    assert not bad, bad[:2]


def test_every_xbee_frame_shows_its_type_addresses_and_rf_data(office):
    rec, capture, _ = office
    names = ["navtwin.xbee.type", "navtwin.xbee.src64", "navtwin.xbee.src16",
             "navtwin.xbee.options", "navtwin.xbee.rf_data", "navtwin.xbee.modem_status",
             "navtwin.xbee.checksum_ok"]
    shown = []
    for row in fields(capture, *names,
                      where='frame.interface_name == "xbee"'):
        types = row[0]
        per = {n: iter(v) for n, v in zip(names[1:], row[1:])}
        for t in types:
            t = int(t, 16)
            f = {"type": t, "ok": next(per["navtwin.xbee.checksum_ok"])}
            if t == xbee.FrameType.RECEIVE_PACKET:
                f.update(src64=next(per["navtwin.xbee.src64"]), src16=next(per["navtwin.xbee.src16"]),
                         options=next(per["navtwin.xbee.options"]),
                         data=next(per["navtwin.xbee.rf_data"]))
            elif t == xbee.FrameType.MODEM_STATUS:
                f.update(status=next(per["navtwin.xbee.modem_status"]))
            shown.append(f)
    expected = _records(rec, "xbee", "xbee")
    assert len(shown) == len(expected) and len(expected) > 200
    assert {r["type"] for r in expected} == {0x8A, 0x90}
    for s, e in zip(shown, expected):
        assert s["type"] == e["type"] and s["ok"] == "1"
        if e["type"] == 0x90:
            assert (int(s["src64"], 16), int(s["src16"], 16), int(s["options"], 16),
                    s["data"].upper()) == (int(e["src64"], 16), int(e["src16"], 16),
                                           e["options"], e["data"])
        else:
            assert int(s["status"], 16) == e["status"]


def test_the_sins_frames_inside_0x90_packets_are_dissected(office):
    """The RF data is the SINS stream: the frames whole in one packet equal those the host
    rebuilds from the coordinator's port (navtwin decode --format xbee-sins)."""
    rec, capture, _ = office
    shown = _sins_frames(capture, 'frame.interface_name == "xbee"')
    expected = {r["seq"]: _expected_sins(r) for r in _records(rec, "xbee-sins", "xbee")
                if r["format"] == "sins"}
    assert len(shown) > 150
    assert all(_same(s, expected[int(s[0])]) for s in shown)


def test_every_nanoloc_report_shows_its_fields_and_distance(office):
    rec, capture, _ = office
    names = ["seq", "t_us", "anchor", "tag", "status", "rssi", "tau1", "tau2", "tau3", "tau4",
             "distance_m", "crc_ok"]
    rows = fields(capture, *(f"navtwin.nanoloc.{n}" for n in names),
                  where='frame.interface_name == "nanoloc"')
    shown = [list(f) for row in rows for f in zip(*row)]
    expected = [[r["seq"], r["t_us"], r["anchor"], r["tag"], r["status"], r["rssi"],
                 *r["tau_ps"], r["distance_m"], True] for r in _records(rec, "nanoloc", "nanoloc")]
    assert len(shown) == len(expected) == 80
    assert all(r["complete"] for r in _records(rec, "nanoloc", "nanoloc"))
    bad = [(s, e) for s, e in zip(shown, expected) if not _same(s, e)]
    assert not bad, bad[:2]


def test_a_flipped_bit_flags_that_sins_frames_crc(office, tmp_path):
    rec, _, _ = office
    damaged = recorded.copy(rec, tmp_path / "damaged")
    recorded.flip_bit(damaged, "sins", 37 * sins.FRAME_SIZE + 10, bit=3)  # frame 37's YGYRO
    capture = tmp_path / "damaged.pcapng"
    with open(capture, "wb") as f:
        write_recording(Recording(damaged), f)
    frames = _sins_frames(capture, 'frame.interface_name == "sins"')
    assert len(frames) == 200
    assert [int(f[0]) for f in frames if f[-1] == "0"] == [37]
    bad = fields(capture, "frame.number", "_ws.expert.message",
                 where="navtwin.sins.crc_ok == 0")
    assert len(bad) == 1 and "Bad CRC-16" in bad[0][1]


def _synthetic(directory, meta_ports: dict, chunks: list, faults=()) -> Recording:
    """A recording of *chunks* (port, data, t_device_ns, t_wall_ns) with the ledger *faults*."""
    with RecordingWriter(directory, {"ports": meta_ports}) as w:
        for port, data, dev, wall in chunks:
            w.port(port).write(data, dev, wall)
        for entry in faults:
            w.fault(entry)
    return Recording(directory)


AT_DB = xbee.build(0x08, frame_id=1, command=b"DB", parameter=b"")
AT_AP = xbee.build(0x08, frame_id=2, command=b"AP", parameter=b"")


def _rx(data: bytes, escaped: bool = True) -> bytes:
    return xbee.build(0x90, escaped, src64=0x0013A20040A1B2D4, src16=0x7E11, options=1, data=data)


def test_a_host_recording_has_wall_times_and_its_writes_outbound_on_xbee(tmp_path):
    """A host recording: wall times only; xbee.tx (what the host wrote to the coordinator)
    is the xbee interface's outbound direction. Its 16-bit source 7E11 and the RF data's
    bytes are escaped on the wire: dissected from the unescaped bytes."""
    frame = sins.build_sample(0x117E, [0x8000] * 11)
    response = xbee.build(0x88, frame_id=1, command=b"DB", status=0, value=b"\x28")
    rec = _synthetic(tmp_path / "host", {"xbee": {"baud": 115200}, "xbee.tx": {"of": "xbee"}}, [
        ("xbee.tx", AT_DB + AT_AP, None, 1000), ("xbee", response, None, 2000),
        ("xbee", _rx(frame), None, 3000)])
    out = io.BytesIO()
    written = write_recording(rec, out)
    assert written.clock == "wall" and written.packets == {"xbee": 3}
    capture = tmp_path / "host.pcapng"
    capture.write_bytes(out.getvalue())
    rows = packets(capture)
    assert [(r["interface"], r["direction"], _ns(r["time"]), r["data"]) for r in rows] == [
        ("xbee", OUTBOUND, 1000, AT_DB + AT_AP), ("xbee", INBOUND, 2000, response),
        ("xbee", INBOUND, 3000, _rx(frame))]
    assert _rx(frame).count(0x7D) >= 2  # the test means what it says: escapes in there
    shown = fields(capture, "navtwin.xbee.type", "navtwin.xbee.command", "navtwin.xbee.value",
                   "navtwin.xbee.src16", "navtwin.xbee.rf_data", "navtwin.sins.seq")
    assert shown[0][:2] == [["0x08", "0x08"], ["DB", "AP"]]
    assert shown[1][:3] == [["0x88"], ["DB"], ["28"]]
    assert shown[2][0] == ["0x90"] and int(shown[2][3][0], 16) == 0x7E11
    assert bytes.fromhex(shown[2][4][0]) == frame and shown[2][5] == [str(0x117E)]


def test_api_mode_1_garbage_and_frames_split_across_packets(tmp_path):
    """Several frames in a packet are all dissected; bytes of no complete frame (garbage,
    a frame's part at a packet's edge) show as garbage, and the search resyncs."""
    a, b = sins.build_sample(1, [0x8000] * 11), sins.build_sample(2, [0x8000] * 11)
    rec = _synthetic(tmp_path / "r", {"sins": {}, "xbee": {"api_mode": 1}}, [
        ("sins", b"\x00\xa5junk" + a + b[:10], 10, None), ("sins", b[10:] + a, 20, None),
        ("xbee", AT_DB[:4], 30, None), ("xbee", AT_DB[4:] + _rx(a, escaped=False), 40, None)])
    capture = tmp_path / "r.pcapng"
    with open(capture, "wb") as f:
        write_recording(rec, f)
    rows = fields(capture, "navtwin.sins.seq", "navtwin.garbage.data", "navtwin.xbee.type")
    assert rows[0][:2] == [["1"], ["00a56a756e6b", b[:10].hex()]]
    assert rows[1][:2] == [["1"], [b[10:].hex()]]
    assert rows[2][1:] == [[AT_DB[:4].hex()], []]
    assert rows[3][1:] == [[AT_DB[4:].hex()], ["0x90"]] and rows[3][0] == ["1"]


def test_fault_entries_and_the_other_clock_go_in_the_comments(tmp_path):
    frame = sins.build_sample(1, [0x8000] * 11)
    rec = _synthetic(tmp_path / "r", {"sins": {}}, [
        ("sins", frame, 10, 110), ("sins", frame, 20, 120), ("sins", frame, 30, 130)],
        faults=[{"kind": "bit_errors", "fault": 0, "port": "sins", "direction": "to_host",
                 "t_ns": 15, "start": 35, "end": 36},
                {"kind": "byte_drop", "fault": 1, "port": "sins", "direction": "to_host",
                 "t_ns": 25, "start": 60, "end": 60, "removed": 1}])
    capture = tmp_path / "r.pcapng"
    with open(capture, "wb") as f:
        write_recording(rec, f)
    assert [r["comment"] for r in packets(capture)] == [
        "t_wall_ns=110", "t_wall_ns=120; fault bit_errors #0 bytes 35..36",
        "t_wall_ns=130; fault byte_drop #1 at byte 60"]
    with open(capture, "wb") as f:
        assert write_recording(rec, f, clock="wall").clock == "wall"
    assert [(_ns(r["time"]), r["comment"].split(";")[0]) for r in packets(capture)] == [
        (110, "t_device_ns=10"), (120, "t_device_ns=20"), (130, "t_device_ns=30")]


def test_no_wall_times_is_an_error_naming_the_clock(office):
    rec, _, _ = office
    with pytest.raises(CaptureError, match=r"^clock: .*no wall times"):
        write_recording(Recording(rec), io.BytesIO(), clock="wall")


def test_a_recordings_streams_merge_in_time_order_on_their_own_interfaces(tmp_path):
    """A stream that is not a port (the air) is an interface of its own with the stream's
    link type and doc, its packets merged with the ports' in time order."""
    frame = sins.build_sample(1, [0x8000] * 11)
    with RecordingWriter(tmp_path / "r", {"ports": {"sins": {}}}) as w:
        w.port("sins").write(frame, 10, None)
        w.stream("air", UNDISSECTED, "the radio").write(b"\x01", 20, None)
        w.port("sins").write(frame, 30, None)
        w.stream("air", UNDISSECTED, "the radio").write(b"\x02", 40, None)
    capture = tmp_path / "r.pcapng"
    with open(capture, "wb") as f:
        written = write_recording(Recording(tmp_path / "r"), f)
    assert written.packets == {"sins": 2, "air": 2}
    assert [(r["interface"], _ns(r["time"])) for r in packets(capture)] == [
        ("sins", 10), ("air", 20), ("sins", 30), ("air", 40)]


def test_damaged_and_random_packets_never_break_the_dissectors(tmp_path):
    """Frames of every type the dissectors know, several to a packet, then a bit flipped,
    the head or tail cut, or random bytes instead: every packet dissects without a Lua error."""
    rnd = random.Random(19)
    words = [0x8000] * 11
    frames = [xbee.frame_data(0x95, src64=1, src16=0x7E7D, options=3, remote16=3, remote64=4,
                              ni="LAB-COORD", parent16=0xFFFE, device_type=1, source_event=1,
                              profile=0xC105, manufacturer=0x101E, device_type_id=0x11),
              xbee.frame_data(0x8B, frame_id=1, dest16=0x7D84, retries=0, delivery=0,
                              discovery=1),
              xbee.frame_data(0x10, frame_id=1, dest64=0x13, dest16=0xFFFE, radius=0, options=0,
                              data=b"\x11\x13"),
              xbee.frame_data(0x97, frame_id=1, src64=1, src16=2, command=b"NI", status=0,
                              value=b"abc"),
              xbee.frame_data(0x91, src64=1, src16=2, src_endpoint=0, dest_endpoint=0,
                              cluster=0x8002, profile=0, options=1, data=b"\x01\x00"),
              xbee.frame_data(0x90, src64=1, src16=2, options=1,
                              data=sins.build_sample(7, words)),
              bytes([0x42, 1, 2]), bytes([0x95]), bytes([0x8B, 1])]
    valid = {"sins": [sins.build_sample(i, words) for i in range(3)],
             "nanoloc": [nanoloc.build_report(seq=1, t_us=2, anchor=1, tag=16, status=s, rssi=-60,
                                              tau=[4, 3, 2, 1]) for s in (0x0F, 0x40, 0x80)],
             "xbee_escaped": [xbee.wrap(d, True) for d in frames],
             "xbee": [xbee.wrap(d, False) for d in frames]}
    linktype = {fmt + ("_escaped" if escaped else ""): lt for (fmt, escaped), lt in LINKTYPES.items()}
    capture, n = tmp_path / "damaged.pcapng", 0
    with open(capture, "wb") as f:
        w = Writer(f)
        for name, vs in valid.items():
            interface = w.interface(name, linktype[name])
            for _ in range(150):
                data = bytearray(b"".join(rnd.choice(vs) for _ in range(rnd.randrange(1, 4))))
                damage = rnd.randrange(5)
                if damage == 1:
                    data[rnd.randrange(len(data))] ^= 1 << rnd.randrange(8)
                elif damage == 2:
                    data = data[rnd.randrange(len(data)):]
                elif damage == 3:
                    data = data[:rnd.randrange(1, len(data) + 1)]
                elif damage == 4:
                    data = bytearray(rnd.randbytes(rnd.randrange(1, 64)))
                w.packet(interface, n, bytes(data))
                n += 1
    shown = fields(capture, "frame.number", "_ws.lua.text", "_ws.expert.message")
    assert len(shown) == n
    assert not [row for row in shown if any("Lua" in m for m in row[1] + row[2])]
