"""Recordings: what is written is read back, chunk for chunk, and merged in time order."""
import json

import pytest

from navtwin.protocols.recording import Recording, RecordingError, RecordingWriter


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
