"""Recordings that survive crashes and full disks, and readers that validate (issue 7, points
5 and 6): the writer's on-disk state is always a replayable prefix; the reader turns every
damaged shape into one RecordingError line and skips only what a crash leaves."""
import json
import os
import resource

import pytest

from navtwin.protocols.recording import (FLUSH_BYTES, META, Recording, RecordingError,
                                 RecordingWriteError, RecordingWriter)

CHUNKS = [(b"abc", 10), (b"defg", 20), (b"hi", 30), (b"jklmn", 40)]


def make(tmp_path, complete=True, name="rec"):
    d = tmp_path / name
    w = RecordingWriter(d, {"source": "test", "ports": {"xbee": {"baud": 115200}}})
    for data, t in CHUNKS:
        w.port("xbee").write(data, t_device_ns=t, t_wall_ns=t + 1)
    if complete:
        w.close()
    else:
        w.flush()  # then "killed": no close
    return d


def set_complete(d, value):
    meta = json.loads((d / META).read_text())
    if value is None:
        meta.pop("complete")
    else:
        meta["complete"] = value
    (d / META).write_text(json.dumps(meta))


def one_line(exc) -> str:
    msg = str(exc.value)
    assert "\n" not in msg and "Traceback" not in msg
    return msg


def test_meta_says_incomplete_from_the_start_and_complete_after_close(tmp_path):
    d = tmp_path / "rec"
    w = RecordingWriter(d, {"ports": {"sins": {"baud": 115200}}})
    assert json.loads((d / META).read_text())["complete"] is False
    assert (d / "sins.csv").read_bytes().count(b"\n") == 1  # the header; chunks are buffered
    w.port("sins").write(b"xyz", t_device_ns=5)
    w.close()
    assert json.loads((d / META).read_text())["complete"] is True
    assert not (d / (META + ".tmp")).exists()
    assert Recording(d).read_bytes("sins") == b"xyz"


def test_an_unclosed_writer_leaves_the_flushed_prefix(tmp_path):
    d = tmp_path / "rec"
    w = RecordingWriter(d, {"ports": {"xbee": {"baud": 115200}}})
    w.port("xbee").write(b"one", t_device_ns=1)
    w.flush()
    w.port("xbee").write(b"two", t_device_ns=2)  # buffered when the process dies
    rec = Recording(d)
    assert not rec.complete and rec.skipped == {}
    assert [c.data for c in rec.chunks("xbee")] == [b"one"]
    assert "incomplete" in rec.skipped_line()


def test_the_writer_flushes_itself_when_its_buffer_is_full(tmp_path):
    d = tmp_path / "rec"
    w = RecordingWriter(d, {"ports": {"xbee": {}}})
    block = bytes(4096)
    for i in range(FLUSH_BYTES // len(block) + 1):
        w.port("xbee").write(block, t_device_ns=i)
    assert w.buffered < FLUSH_BYTES
    assert (d / "xbee.bin").stat().st_size >= FLUSH_BYTES // 2
    assert sum(1 for _ in Recording(d).chunks("xbee")) >= (FLUSH_BYTES // 2) // len(block)


def test_a_failing_write_leaves_an_incomplete_replayable_recording(tmp_path):
    d = tmp_path / "rec"
    w = RecordingWriter(d, {"ports": {"xbee": {}}})
    w.port("xbee").write(b"kept", t_device_ns=1)
    w.flush()
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (2048, limit[1]))
    try:
        w.port("xbee").write(bytes(4000), t_device_ns=2)
        with pytest.raises(RecordingWriteError) as e:
            w.flush()
        assert "xbee.bin" in one_line(e) and "ulimit -f" in str(e.value)
        w.port("xbee").write(b"after", t_device_ns=3)  # ignored: the recording ended
        w.close()  # the failure was raised once; close does not raise it again
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, limit)
    meta = json.loads((d / META).read_text())
    assert meta["complete"] is False and "xbee.bin" in meta["write_error"]
    rec = Recording(d)
    assert [c.data for c in rec.chunks("xbee")] == [b"kept"]
    assert rec.skipped["xbee"]["bytes"] == 2048 - 4  # written data the index never named


def test_the_writer_never_writes_through_a_symlink(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    (tmp_path / "link").symlink_to(real)
    with pytest.raises(RecordingWriteError) as e:
        RecordingWriter(tmp_path / "link", {"ports": {"xbee": {}}})
    assert "symbolic link" in one_line(e) and not any(real.iterdir())
    # a symlinked file inside a recording that is being replaced is not followed either
    victim = tmp_path / "victim"
    victim.write_text("not navtwin's")
    d = make(tmp_path)
    (d / "xbee.bin").unlink()
    (d / "xbee.bin").symlink_to(victim)
    with pytest.raises(RecordingWriteError) as e:
        RecordingWriter(d, {"ports": {"xbee": {}}}, replace=True)
    assert "symbolic link" in one_line(e) and victim.read_text() == "not navtwin's"


BAD_META = {
    "top level a list": b"[]",
    "top level a string": b'"navtwin"',
    "top level null": b"null",
    "empty file": b"",
    "not JSON": b"{",
    "not UTF-8": b'{"format": "navtwin-recording\xff"}',
    "no format": {"format": None},
    "wrong format": {"format": "pcap"},
    "version a string": {"version": "1"},
    "version zero": {"version": 0},
    "version newer": {"version": 99},
    "complete a string": {"complete": "yes"},
    "ports a list": {"ports": ["xbee"]},
    "ports missing": {"ports": None},
    "ports empty": {"ports": {}},
    "port a number": {"ports": {"xbee": 115200}},
    "port name with a path": {"ports": {"../../etc/passwd": {}}},
    "baud 0": {"ports": {"xbee": {"baud": 0}}},
    "baud negative": {"ports": {"xbee": {"baud": -115200}}},
    "baud a string": {"ports": {"xbee": {"baud": "fast"}}},
    "baud a float": {"ports": {"xbee": {"baud": 115200.0}}},
    "baud a bool": {"ports": {"xbee": {"baud": True}}},
    "baud absurd": {"ports": {"xbee": {"baud": 10 ** 12}}},
    "api_mode 3": {"ports": {"xbee": {"baud": 115200, "api_mode": 3}}},
}


@pytest.mark.parametrize("shape", BAD_META)
def test_bad_recording_json_is_one_line_error(tmp_path, shape):
    d = make(tmp_path)
    bad = BAD_META[shape]
    if isinstance(bad, dict):
        meta = {**json.loads((d / META).read_text()), **bad}
        meta = {k: v for k, v in meta.items() if v is not None}
        bad = json.dumps(meta).encode()
    (d / META).write_bytes(bad)
    with pytest.raises(RecordingError) as e:
        Recording(d)
    assert "recording.json" in one_line(e)


@pytest.mark.parametrize("line, problem", [
    (b"-3,4,20,21", "non-negative integers"),  # negative offset
    (b"3,-4,20,21", "non-negative integers"),
    (b"4,4,20,21", "not where the previous chunk ends"),  # not contiguous
    (b"99999,4,20,21", "not where the previous chunk ends"),  # offset past the data
    (b"3,0,20,21", "size 0"),
    (b"3,%d,20,21" % 10 ** 15, "size 1000000000000000"),  # "the rest fed twice" before
    (b"3,4,20", "expected offset,size"),
    (b"3,4,x,21", "non-negative integers"),
    (b"3,4,\xff\xfe,21", "non-negative integers"),  # not ASCII
    (b"3,4,9,21", "t_device_ns 9 is before"),
    (b"3,4,20,5", "t_wall_ns 5 is before"),
    (b"3," + b"4" * 200 + b",20,21", "longer than"),
])
def test_impossible_index_entries_are_errors_naming_file_and_line(tmp_path, line, problem):
    d = make(tmp_path)
    lines = (d / "xbee.csv").read_bytes().splitlines()
    lines[2] = line
    (d / "xbee.csv").write_bytes(b"\n".join(lines) + b"\n")
    set_complete(d, False)  # impossible even for a crash: not forgiven as a truncated tail
    with pytest.raises(RecordingError) as e:
        Recording(d)
    assert "xbee.csv:3: " in one_line(e) and problem in str(e.value)


def test_a_wrong_header_is_an_error(tmp_path):
    d = make(tmp_path)
    (d / "xbee.csv").write_bytes(b"offset;size\n0,3,10,11\n")
    with pytest.raises(RecordingError, match=r"xbee\.csv:1: the first line"):
        Recording(d)


@pytest.mark.parametrize("complete", [True, None])  # None: a recording from before the flag
def test_data_cut_under_an_intact_index_is_damage_unless_salvaged(tmp_path, complete):
    d = make(tmp_path)
    set_complete(d, complete)
    os.truncate(d / "xbee.bin", 7)  # half of the 14 bytes
    with pytest.raises(RecordingError) as e:
        Recording(d)
    assert "xbee.csv:4: chunks past the end of xbee.bin" in one_line(e) and "--salvage" in str(e.value)
    rec = Recording(d, salvage=True)
    assert [c.data for c in rec.chunks("xbee")] == [b"abc", b"defg"]
    assert rec.skipped["xbee"] == {"chunks": 2, "bytes": 0,
                                   "why": "chunks past the end of xbee.bin (7 bytes)"}
    assert "salvaged" in rec.skipped_line()


def test_a_crash_tail_of_an_incomplete_recording_is_skipped_and_reported(tmp_path):
    d = make(tmp_path, complete=False)
    with open(d / "xbee.csv", "ab") as f:
        f.write(b"14,3,5")  # a partial last line
    rec = Recording(d)
    assert [c.data for c in rec.chunks("xbee")] == [b for b, _ in CHUNKS]
    assert rec.skipped["xbee"] == {"chunks": 1, "bytes": 0, "why": "a partial last index line"}
    os.truncate(d / "xbee.bin", 10)
    rec = Recording(d)
    assert [c.data for c in rec.chunks("xbee")] == [b"abc", b"defg", b"hi"]
    assert rec.skipped["xbee"]["chunks"] == 2 and "incomplete" in rec.skipped_line()


def test_chunks_are_read_one_at_a_time_not_the_file_whole(tmp_path, monkeypatch):
    d = make(tmp_path)
    os.truncate(d / "xbee.bin", 3 << 30)  # sparse: 3 GiB, of which the index names 14 bytes
    reads = []
    real_open = open

    class Spy:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *a):
            self.f.close()

        def fileno(self):
            return self.f.fileno()

        def read(self, n=-1):
            reads.append(n)
            return self.f.read(n)

    def spy_open(path, mode="r", *a, **kw):
        f = real_open(path, mode, *a, **kw)
        return Spy(f) if str(path).endswith(".bin") else f

    monkeypatch.setattr("builtins.open", spy_open)
    rec = Recording(d)
    assert [c.data for c in rec.chunks("xbee")] == [b for b, _ in CHUNKS]
    assert reads == [len(b) for b, _ in CHUNKS]
    assert rec.skipped["xbee"]["bytes"] == (3 << 30) - 14
