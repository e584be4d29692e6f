"""Fuzz target: the recording reader (protocols.recording.Recording) on a directory whose
recording.json, sins.csv and sins.bin come from the input."""
import json

from navtwin.protocols.recording import META, READS_HEADER, Recording, RecordingError

from .harness import Input, check_reader, fixture

PORT = "sins"  # the port whose files the input gives; the meta may name others (missing)


def _input(meta: bytes, index: bytes, data: bytes, salvage: bool) -> bytes:
    """The input that :func:`check` reads back as these files (control values at the end)."""
    return meta + index + data + int(salvage).to_bytes(2, "big") + len(index).to_bytes(2, "big") + \
        len(meta).to_bytes(2, "big")


def _seeds() -> list[bytes]:
    meta = json.dumps({"format": "navtwin-recording", "version": 1, "complete": True,
                       "ports": {PORT: {"baud": 115200}}}).encode()
    index = fixture("golden", "office", "sins.csv", size=400)
    index = index[:index.rindex(b"\n") + 1]
    data = fixture("golden", "office", "sins.bin", size=1200)  # more than the index names
    incomplete = meta.replace(b"true", b"false")
    # a host's index: the read columns (version 2), one read reordered
    lines = index.splitlines()[1:]
    reads = [line + b",%s,0,0" % line.split(b",")[0] for line in lines]
    reads[1:3] = [b",".join(a.split(b",")[:4] + b.split(b",")[4:]) for a, b in
                  zip(reads[1:3], reads[2:0:-1])]
    host = READS_HEADER.encode() + b"\n" + b"\n".join(reads) + b"\n"
    v2 = meta.replace(b'"version": 1', b'"version": 2')
    return [_input(meta, index, data, False), _input(incomplete, index + b"1200,30,1", data, True),
            _input(v2, host, data, False), _input(v2, host + b"1200,30,,,,", data, True),
            _input(meta, index, data[:100], True),
            # json's limits: nesting past the recursion limit, an integer past 4300 digits
            _input(b"[" * 2000 + b"]" * 2000, index, data, False),
            _input(meta.replace(b'"version": 1', b'"version": ' + b"1" * 4400), index, data, False)]


SEEDS = _seeds()


def verify(rec: Recording, directory) -> None:
    """What a replay relies on: each port's chunks are its data file's bytes in order, from
    offset 0, with non-decreasing times, and the summary of what was skipped is one line."""
    for port in rec.ports:
        data = (directory / f"{port}.bin").read_bytes()
        offset, last = 0, [-1, -1]
        for c in rec.chunks(port):
            assert c.offset == offset and c.data == data[offset:offset + len(c.data)] and c.data
            offset += len(c.data)
            for i, t in enumerate((c.t_device_ns, c.t_wall_ns)):
                if t is not None:
                    assert t >= last[i]
                    last[i] = t
        assert offset == rec.sizes[port]
    assert sum(1 for _ in rec.merged()) == sum(1 for p in rec.ports for _ in rec.chunks(p))
    line = rec.skipped_line()
    assert line is None or "\n" not in line


def check(data: bytes) -> None:
    inp = Input(data)
    meta, index = inp.bytes(inp.int(1 << 16)), inp.bytes(inp.int(1 << 16))
    salvage = inp.int(2) == 1
    check_reader(lambda d: Recording(d, salvage=salvage), RecordingError,
                 {META: meta, f"{PORT}.csv": index, f"{PORT}.bin": inp.rest()}, verify)
