"""What every fuzz target shares: splitting an input, and the decoder and reader contracts.

A target module defines ``SEEDS`` (inputs built in code from real frames, shipped scenarios
and fixtures) and ``check(data)``, which raises AssertionError (or anything else) when a
contract is broken. ``python -m tests.fuzz`` runs it under atheris, or with ``--replay`` on its
seeds without atheris, so the contract checks run in every test run.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

from navtwin.protocols.stream import MALFORMED, DecodeError, Frame

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures"


class Input:
    """One fuzz input read two ways: control values from its end, data from its front (as
    atheris.FuzzedDataProvider does; this one is plain Python, so a crash file gives the same
    values when it is replayed without atheris)."""

    def __init__(self, data: bytes) -> None:
        self._data = data
        self._end = len(data)
        self._start = 0

    def int(self, n: int) -> int:
        """An int in 0..n-1 from the last two unread bytes (0 once they run out)."""
        if self._end - self._start < 2:
            return 0
        self._end -= 2
        return int.from_bytes(self._data[self._end:self._end + 2], "big") % n

    def bytes(self, n: int) -> bytes:
        """Up to *n* bytes from the front."""
        out = self._data[self._start:min(self._start + n, self._end)]
        self._start += len(out)
        return out

    def rest(self) -> bytes:
        return self.bytes(self._end - self._start)


# -- decoders ------------------------------------------------------------------------------

def split(inp: Input, most: int = 24):
    """A chunking chosen by the input (read before the stream): stream -> chunks."""
    at = [inp.int(1 << 16) for _ in range(inp.int(most + 1))]

    def chunks(stream: bytes) -> list[bytes]:
        bounds = [0, *sorted(a * len(stream) >> 16 for a in at), len(stream)]
        return [stream[a:b] for a, b in zip(bounds, bounds[1:]) if b > a]
    return chunks


def event(e) -> tuple:
    """An event as comparable values: all that a consumer of the decoder sees."""
    if isinstance(e, Frame):
        return ("frame", e.format, e.source, e.offset, e.raw, e.type, e.known, repr(e.fields))
    return ("error", e.format, e.source, e.kind, e.offset, e.size)


def feed(dec, chunks, bounded) -> list[tuple]:
    """Feed *chunks* then flush; after each feed ``bounded(dec, chunk)`` checks the memory."""
    out = []
    for c in chunks:
        out += dec.feed(c)
        bounded(dec, len(c))
    return [event(e) for e in out + dec.flush()]


def claims(events) -> list[tuple[int, int]]:
    """(start, end) of every candidate that passed its integrity check: only those consume
    bytes beyond their first, so only they can swallow a later frame."""
    out = []
    for e in events:
        if isinstance(e, Frame):
            out.append((e.offset, e.offset + len(e.raw)))
        elif isinstance(e, DecodeError) and e.kind == MALFORMED:
            out.append((e.offset, e.offset + e.size))
    return out


def assert_recovered(events, expected, lossless: bool) -> None:
    """Every (offset, raw) frame of *expected* is among the *events*; in a lossy format
    (stream.py, "Worst case loss") a frame may instead be covered by a false candidate that
    began before it and passed its integrity check."""
    got = {(e.offset, e.raw) for e in events if isinstance(e, Frame)}
    covering = claims(events)
    for offset, raw in expected:
        if (offset, raw) in got:
            continue
        assert not lossless and any(a < offset < b for a, b in covering), \
            f"the valid frame at {offset} after the garbage was lost: {raw.hex()}"


def framed(start: int, frames: list[bytes]) -> list[tuple[int, bytes]]:
    """(offset, raw) of *frames* laid end to end from *start*."""
    out = []
    for f in frames:
        out.append((start, f))
        start += len(f)
    return out


def check_decoder(make, data: bytes, *, bound: int, tail: list[bytes], lossless: bool) -> None:
    """The contracts of a framed decoder (protocols/stream.py) on one input: it never raises;
    its buffer stays within *bound* plus the chunk fed; any chunking gives the same events as
    one piece; every byte is a frame's or garbage's; the valid frames *tail* appended after
    the input are all recovered."""
    inp = Input(data)
    chunks = split(inp)
    stream = inp.rest()

    def bounded(dec, chunk):
        assert dec.buffered <= bound + chunk, f"buffer {dec.buffered} > {bound} + {chunk}"

    whole = feed(make(), [stream], bounded)
    assert feed(make(), chunks(stream), bounded) == whole, "another chunking, other events"

    dec = make()
    full = stream + b"".join(tail)
    events = dec.decode(full)
    frame_bytes = sum(len(e.raw) for e in events if isinstance(e, Frame))
    assert dec.bytes == len(full) == frame_bytes + dec.error_bytes["garbage"], \
        "bytes != frame bytes + garbage bytes"
    assert dec.frames == sum(isinstance(e, Frame) for e in events)
    assert_recovered(events, framed(len(stream), tail), lossless)


# -- readers -------------------------------------------------------------------------------

def check_reader(read, error: type, files: dict[str, bytes], verify=None) -> None:
    """Write *files* (name -> content) into a fresh directory and ``read(directory)``: it
    raises *error* with a one-line message, or gives a result that ``verify(result,
    directory)`` checks; anything else raised is a broken contract."""
    with tempfile.TemporaryDirectory(dir=_scratch()) as d:
        for name, content in files.items():
            Path(d, name).write_bytes(content)
        try:
            result = read(Path(d))
        except error as e:
            message = str(e)
            assert message and "\n" not in message, f"not one line: {message!r}"
            return
        if verify is not None:
            verify(result, Path(d))


def fixture(*parts: str, size: int | None = None) -> bytes:
    """The first *size* bytes of a file under fixtures/ (a shipped recording, a config)."""
    return (FIXTURES.joinpath(*parts)).read_bytes()[:size]


def _scratch() -> str | None:
    """Memory-backed scratch space where there is one: a million inputs write a million
    directories."""
    shm = Path("/dev/shm")
    return str(shm) if shm.is_dir() else None
