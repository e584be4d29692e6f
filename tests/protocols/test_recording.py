"""Recordings: what is written is read back, chunk for chunk, and merged in time order."""
import json
import re

import pytest

from navtwin.protocols.recording import Read, Recording, RecordingError, RecordingWriter, Stream


def test_round_trip_and_merge(tmp_path):
    with RecordingWriter(tmp_path, {"source": "test", "ports": {"xbee": {"baud": 115200}}}) as w:
        w.port("xbee").write(b"ab", t_device_ns=10, t_wall_ns=5)
        w.port("sins").write(b"cde", t_device_ns=10)
        w.port("xbee").write(b"f", t_device_ns=30, t_wall_ns=7)
        w.port("sins").write(b"", t_device_ns=40)  # empty writes are not chunks
        w.port("sins").write(b"g", t_device_ns=20)
    rec = Recording(tmp_path)
    assert rec.ports == ["sins", "xbee"]
    assert rec.meta["ports"]["xbee"] == {"baud": 115200} and rec.meta["source"] == "test"
    assert rec.read_bytes("sins") == b"cdeg"
    assert [(c.offset, c.data, c.t_device_ns, c.t_wall_ns) for c in rec.chunks("xbee")] == \
           [(0, b"ab", 10, 5), (2, b"f", 30, 7)]
    # equal times: port name order, then stream order
    assert [(c.port, c.data) for c in rec.merged(clock="t_device_ns")] == \
           [("sins", b"cde"), ("xbee", b"ab"), ("sins", b"g"), ("xbee", b"f")]


def test_bad_recordings_are_one_line_errors(tmp_path):
    with pytest.raises(RecordingError, match="recording.json"):
        Recording(tmp_path)
    (tmp_path / "recording.json").write_text(json.dumps({"format": "navtwin-recording", "version": 99}))
    with pytest.raises(RecordingError, match="upgrade navtwin"):
        Recording(tmp_path)
    (tmp_path / "recording.json").write_text("{")
    with pytest.raises(RecordingError, match="not valid JSON"):
        Recording(tmp_path)


@pytest.mark.parametrize("meta, problem", [
    (b"[" * 2000 + b"]" * 2000, "arrays or objects nested too deeply"),
    (b'{"format": "navtwin-recording", "version": ' + b"1" * 4400 + b"}",
     "an integer of more than 4300 digits"),
])
def test_a_meta_past_jsons_limits_is_a_one_line_error(tmp_path, meta, problem):
    """The recording fuzz target's seeds: RecursionError and ValueError escaped the reader."""
    (tmp_path / "recording.json").write_bytes(meta)
    with pytest.raises(RecordingError) as e:
        Recording(tmp_path)
    assert problem in str(e.value) and "\n" not in str(e.value)


def test_a_hosts_read_columns_round_trip_in_a_version_2_recording(tmp_path):
    with RecordingWriter(tmp_path / "host", {"ports": {"xbee": {}, "xbee.tx": {}}},
                         reads=True) as w:
        w.port("xbee").write(b"ab", t_wall_ns=5, read=Read(0, 0, 0))
        w.port("xbee").write(b"cde", t_wall_ns=7, read=Read(40, 1, 3))
        w.port("xbee.tx").write(b"q", t_wall_ns=7)  # sent, not read: empty columns
    rec = Recording(tmp_path / "host")
    assert rec.meta["version"] == 2 and rec.reads == {"xbee": True, "xbee.tx": True}
    assert [(c.data, c.t_wall_ns, c.read) for c in rec.chunks("xbee")] == \
           [(b"ab", 5, Read(0, 0, 0)), (b"cde", 7, Read(40, 1, 3))]
    assert [c.read for c in rec.chunks("xbee.tx")] == [None]
    assert (tmp_path / "host" / "xbee.csv").read_text().splitlines() == [
        "offset,size,t_device_ns,t_wall_ns,read_offset,reconnects,contended",
        "0,2,,5,0,0,0", "2,3,,7,40,1,3"]
    # without read columns the recording is what it always was: version 1, four columns
    with RecordingWriter(tmp_path / "emu", {"ports": {"xbee": {}}}) as w:
        w.port("xbee").write(b"ab", t_device_ns=1)
        with pytest.raises(ValueError, match="reads=True"):
            w.port("xbee").write(b"cd", t_device_ns=2, read=Read(2, 0, 0))
    old = Recording(tmp_path / "emu")
    assert old.meta["version"] == 1 and old.reads == {"xbee": False}
    assert [c.read for c in old.chunks("xbee")] == [None]


@pytest.mark.parametrize("line, problem", [
    (b"2,3,,7", "expected offset,size,t_device_ns,t_wall_ns,read_offset,reconnects,contended"),
    (b"2,3,,7,40,,3", "expected non-negative integers offset,size,"),  # two of three
    (b"2,3,,7,40,1,3,9", "expected offset,size"),
])
def test_read_columns_all_or_none_on_every_line(tmp_path, line, problem):
    with RecordingWriter(tmp_path, {"ports": {"xbee": {}}}, reads=True) as w:
        w.port("xbee").write(b"ab", t_wall_ns=5, read=Read(0, 0, 0))
        w.port("xbee").write(b"cde", t_wall_ns=7, read=Read(2, 0, 0))
    index = (tmp_path / "xbee.csv").read_bytes().splitlines()
    (tmp_path / "xbee.csv").write_bytes(b"\n".join(index[:2] + [line]) + b"\n")
    with pytest.raises(RecordingError, match=r"xbee\.csv:3: ") as e:
        Recording(tmp_path)
    assert problem in str(e.value)


def test_read_columns_in_a_version_1_recording_are_damage(tmp_path):
    """An older navtwin meets version 2 and says to upgrade; a version 1 recording never has
    the read columns."""
    with RecordingWriter(tmp_path, {"ports": {"xbee": {}}}, reads=True) as w:
        w.port("xbee").write(b"ab", t_wall_ns=5, read=Read(0, 0, 0))
    meta = json.loads((tmp_path / "recording.json").read_text())
    (tmp_path / "recording.json").write_text(json.dumps({**meta, "version": 1}))
    with pytest.raises(RecordingError, match=r"xbee\.csv:1: the first line must be "
                                             r"'offset,size,t_device_ns,t_wall_ns';"):
        Recording(tmp_path)


def test_a_stream_beside_the_ports_is_read_as_a_port_is_and_listed_apart(tmp_path):
    with RecordingWriter(tmp_path, {"ports": {"xbee": {}}}) as w:
        w.port("xbee").write(b"ab", t_device_ns=10)
        air = w.stream("air", 195, "the radio hop")
        air.write(b"\x02\x00\x05\x12\x34", t_device_ns=3)
        assert w.stream("air", 195, "the radio hop") is air
        air.write(b"\x02\x00\x06\x56\x78", t_device_ns=9)
        with pytest.raises(ValueError, match="also a port"):
            w.stream("xbee", 195, "")
    rec = Recording(tmp_path)
    assert rec.ports == ["xbee"] and list(rec.meta["ports"]) == ["xbee"]
    assert rec.streams == {"air": Stream("air", 195, "the radio hop")}
    assert [(c.port, c.offset, c.t_device_ns) for c in rec.chunks("air")] == \
           [("air", 0, 3), ("air", 5, 9)]
    assert [c.port for c in rec.merged(clock="t_device_ns")] == ["xbee"]  # the ports only


@pytest.mark.parametrize("streams, problem", [
    ([], "streams [] is not an object"),
    ({"xbee": {"linktype": 195}}, "apart from the ports'"),
    ({"../air": {"linktype": 195}}, "not a plain file name"),
    ({"air": {"linktype": "195"}}, "linktype '195' is not an integer"),
    ({"air": {"linktype": 1 << 16}}, "is not an integer from 0 to 65535"),
    ({"air": {"linktype": 195, "doc": 1}}, "doc 1 is not a string"),
])
def test_a_bad_stream_in_the_meta_is_a_one_line_error(tmp_path, streams, problem):
    with RecordingWriter(tmp_path, {"ports": {"xbee": {}}}):
        pass
    meta = json.loads((tmp_path / "recording.json").read_text())
    (tmp_path / "recording.json").write_text(json.dumps({**meta, "streams": streams}))
    with pytest.raises(RecordingError, match=re.escape(problem)):
        Recording(tmp_path)
