"""Streaming decoders: bytes in any chunking -> frames and errors, in stream order.

A decoder never raises on its input. Everything it cannot use is reported as a
:class:`DecodeError` of one of these kinds and counted:

=============  ===============================================================
kind           meaning
=============  ===============================================================
garbage        a run of bytes that belongs to no frame (size = bytes in the run)
bad_crc        a SINS / nanoLOC candidate whose CRC-16 does not match
bad_checksum   an XBee candidate whose checksum does not match
bad_length     a length field no frame of that kind can have
bad_escape     API mode 2: ``7D`` not followed by an escaped byte
truncated      a candidate cut short by the next start delimiter (API 2) or by
               the end of the stream
malformed      integrity check passed, but the body does not fit its type's layout
evicted        xbee-sins chain: the SINS stream of the least recently heard source,
               ended to make room for a new one (size = bytes it still held)
=============  ===============================================================

Sizes. A failed candidate's size is its claimed size (bad_crc, bad_checksum, bad_length,
malformed) or what was read of it (truncated: to the next ``7E`` in API mode 2, or the end
of the stream; bad_escape: up to and including the bad pair), never what a chunk happened
to hold, so the same bytes give the same events in any chunking. The candidate's bytes
then join a garbage run.

Resync rule. A candidate starts at a sync pattern (``A5 5A``, ``4E 4C``, ``7E``). When it
fails, the decoder resumes the search one byte after the failed start (API mode 2: at the
next bare ``7E``, which can only be a frame start), so every byte after a false start is
looked at again and every intact frame after garbage is found. The bytes of failed
candidates end up in garbage runs; ``bytes == frame bytes + garbage bytes + buffered``.

Worst case loss. An intact frame is lost only when a false candidate that starts in the
garbage before it passes the integrity check and claims bytes of the intact frame:
probability 2^-16 per false candidate with a plausible type and length (CRC-16), 2^-8 for
API mode 1 (8-bit checksum). In API mode 2 a candidate ends at the next bare ``7E``, so
garbage can never swallow an intact frame. Memory is bounded: the buffer never holds more
than one maximal candidate plus the last chunk fed, whatever a length field claims.
"""
from __future__ import annotations

import functools
from collections import Counter
from dataclasses import dataclass
from typing import Any

from . import nanoloc, sins, xbee
from .crc import crc16
from .crcframe import HEADER, TRAILER
from .fast import parser_for, picker_for, plain

# one compiled parser per layout, shared by every decoder (a chain makes one per source)
parser_for = functools.cache(parser_for)

GARBAGE = "garbage"
BAD_CRC = "bad_crc"
BAD_CHECKSUM = "bad_checksum"
BAD_LENGTH = "bad_length"
BAD_ESCAPE = "bad_escape"
TRUNCATED = "truncated"
MALFORMED = "malformed"
EVICTED = "evicted"
ERROR_KINDS = (GARBAGE, BAD_CRC, BAD_CHECKSUM, BAD_LENGTH, BAD_ESCAPE, TRUNCATED, MALFORMED,
               EVICTED)
#: SINS streams an XBeeSinsChain keeps (one per source address); the lab has one router, so
#: 64 leaves room for any real network while 100,000 forged addresses stay in bounded memory
MAX_SOURCES = 64


@dataclass(slots=True)
class Frame:
    """A decoded frame. ``fields`` holds the type's layout as plain Python values;
    a type the format does not declare has ``fields == {"payload": bytes}``."""

    format: str  # the protocols.formats name of its layout: "sins", "nanoloc", "xbee", ...
    offset: int  # of the first byte, in the decoder's input stream
    raw: bytes  # the frame as it was on the wire (escaped in API mode 2)
    type: int
    fields: dict[str, Any]
    known: bool = True  # False for a type this format does not declare
    source: int | None = None  # xbee-sins chain: 64-bit address of the sending radio


@dataclass(slots=True)
class DecodeError:
    kind: str
    offset: int
    size: int = 0  # bytes in a garbage run; a failed candidate's size (see the module doc)
    format: str = ""
    source: int | None = None


class Decoder:
    """Base of the framed decoders: buffer, offsets, counts, garbage runs."""

    format = ""

    def __init__(self) -> None:
        self._buf = b""  # the bytes held for the next feed (a candidate waiting for more)
        self._base = 0  # stream offset of _buf[0]
        self._garbage_at = -1  # stream offset where the open garbage run began
        self._out: list = []
        #: stamped on each frame and error: the xbee-sins chain's sending radio of this stream
        self.source: int | None = None
        self.frames = 0
        self.bytes = 0
        self.errors: Counter[str] = Counter()
        self.error_bytes: Counter[str] = Counter()

    # -- public --------------------------------------------------------------------------
    def feed(self, data: bytes) -> list:
        """Decode *data* after all that was fed before; frames and errors in stream order."""
        self.bytes += len(data)
        # one bytes object to scan: what was held, then data (no copy when nothing was held);
        # its slices are then the frames' raw bytes, with no second copy
        buf = self._buf + data if self._buf else bytes(data)
        consumed = self._scan(buf, final=False)
        self._buf = buf[consumed:]
        self._base += consumed
        out, self._out = self._out, []
        return out

    def flush(self) -> list:
        """End of stream: a candidate still waiting for bytes is truncated, and the search
        goes on one byte after it, so no intact frame behind a false start is lost."""
        self._scan(self._buf, final=True)
        self._base += len(self._buf)
        self._buf = b""
        self._close_garbage(self._base)
        out, self._out = self._out, []
        return out

    def decode(self, data: bytes) -> list:
        """Feed all of *data* and flush."""
        return self.feed(data) + self.flush()

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def summary(self) -> dict:
        return {"format": self.format, "frames": self.frames, "bytes": self.bytes,
                "errors": dict(self.errors), "error_bytes": dict(self.error_bytes),
                "buffered": self.buffered}

    # -- for subclasses ------------------------------------------------------------------
    def _scan(self, buf: bytes, final: bool) -> int:
        """Consume from *buf* (held bytes, then the new ones; ``self._base`` is its stream
        offset); return how many leading bytes are done with. With *final* (end of stream)
        every byte must be consumed."""
        raise NotImplementedError

    def _garbage(self, offset: int, size: int) -> None:
        """Bytes [offset, offset+size) belong to no frame."""
        if size and self._garbage_at < 0:
            self._garbage_at = offset

    def _close_garbage(self, end: int) -> None:
        if self._garbage_at >= 0:
            size = end - self._garbage_at
            self.errors[GARBAGE] += 1
            self.error_bytes[GARBAGE] += size
            self._out.append(DecodeError(GARBAGE, self._garbage_at, size, self.format,
                                         self.source))
            self._garbage_at = -1

    def _error(self, kind: str, offset: int, size: int) -> None:
        """A failed candidate at *offset*; its bytes are accounted to garbage later."""
        self._close_garbage(offset)
        self.errors[kind] += 1
        self._out.append(DecodeError(kind, offset, size, self.format, self.source))

    def _accept(self, offset: int, raw: bytes, ftype: int, parser, data, start: int,
                size: int) -> None:
        """An intact frame of *ftype* whose body is ``data[start:start + size]``: parsed by
        *parser* (a :func:`navtwin.protocols.fast.parser_for` pair), kept raw when the type is not
        declared, malformed when the body does not fit its layout."""
        if parser is None:
            fields, known = {"payload": bytes(data[start:start + size])}, False
        else:
            fields, known = parser[0](data, start, size), True
            if fields is None:
                self._error(MALFORMED, offset, len(raw))
                self._garbage(offset, len(raw))
                return
        if self._garbage_at >= 0:
            self._close_garbage(offset)
        self.frames += 1
        self._out.append(Frame(self.format, offset, raw, ftype, fields, known, self.source))


class LengthFramed(Decoder):
    """Frames that start with a sync pattern and say their length in a header: the scan and
    its resync rule, shared by the SINS/nanoLOC framing and XBee API mode 1. A subclass
    gives ``sync``, ``header`` (bytes needed to know the size), ``integrity`` (the error kind
    of a failed check) and the two methods below."""

    sync: bytes
    header: int
    integrity: str

    def _size(self, buf, j: int) -> tuple[int, bool]:
        """(claimed frame size, whether any frame can have it) of the candidate at *j*."""
        raise NotImplementedError

    def _take(self, buf: bytes, j: int, end: int, offset: int) -> bool:
        """Parse and emit the candidate ``buf[j:end]`` (at stream *offset*) if it passes the
        integrity check; whether it did. (One call per frame: the check and the parse.)"""
        raise NotImplementedError

    def _scan(self, buf: bytes, final: bool) -> int:
        base, sync, header = self._base, self.sync, self.header
        size_of, take, garbage = self._size, self._take, self._garbage
        n = len(buf)
        i = 0
        while True:
            j = buf.find(sync, i)
            if j < 0:
                # keep a possible first sync byte at the very end for the next chunk
                keep = n - 1 if len(sync) > 1 and n > i and buf[-1] == sync[0] and not final else n
                garbage(base + i, keep - i)
                return keep
            if j > i:
                garbage(base + i, j - i)
            size, possible = size_of(buf, j) if n - j >= header else (n + 1, True)
            if not possible:  # judged before waiting, so a false length cannot grow the buffer
                self._error(BAD_LENGTH, base + j, size)
            elif j + size > n:
                if not final:
                    return j
                self._error(TRUNCATED, base + j, n - j)
            elif take(buf, j, j + size, base + j):
                i = j + size
                continue
            else:
                self._error(self.integrity, base + j, size)
            self._garbage(base + j, 1)  # resync one byte after the failed start
            i = j + 1


class CrcFramedDecoder(LengthFramed):
    """SINS frames and nanoLOC reports: sync(2) type len payload crc16."""

    header = HEADER
    integrity = BAD_CRC

    def __init__(self, fmt: str, sync: bytes, layouts: dict) -> None:
        super().__init__()
        self.format = fmt
        self.sync = sync
        self._parsers = {t: parser_for(st) for t, st in layouts.items()}

    def _size(self, buf, j: int) -> tuple[int, bool]:
        length = buf[j + 3]
        parser = self._parsers.get(buf[j + 2])
        # a declared type of fixed size must say exactly that; others are skipped by len
        return HEADER + length + TRAILER, parser is None or parser[1] in (None, length)

    def _take(self, buf: bytes, j: int, end: int, offset: int) -> bool:
        if crc16(buf[j + 2:end]):  # the CRC of the covered bytes and the CRC is 0 (crc.py)
            return False
        ftype = buf[j + 2]
        self._accept(offset, buf[j:end], ftype, self._parsers.get(ftype), buf, j + HEADER,
                     buf[j + 3])
        return True


def sins_decoder() -> CrcFramedDecoder:
    return CrcFramedDecoder("sins", sins.SYNC, sins.LAYOUTS)


def nanoloc_decoder() -> CrcFramedDecoder:
    return CrcFramedDecoder("nanoloc", nanoloc.SYNC, nanoloc.LAYOUTS)


_XBEE_PARSERS = {t: parser_for(st) for t, st in xbee.FRAME_BODIES.items()}


def _raw_extent(seg, need: int) -> int:
    """Raw bytes of validly escaped *seg* that unescape to its first *need* bytes: *need*
    plus the 7D of each pair among them. (Counting the unescaped bytes that are escapable
    overcounts a sender's bare 11 or 13, and so took the next frame's 7E into this one.)"""
    end = need
    while (n := need + seg.count(xbee.ESCAPE, 0, end)) != end:
        end = n
    return end


_RECEIVE_PACKET = int(xbee.FrameType.RECEIVE_PACKET)
_pick_payload = picker_for(xbee.FRAME_BODIES[_RECEIVE_PACKET], "src64", "data")


class XBeeDecoder(LengthFramed):
    """XBee API frames in API mode 1 (``escaped=False``) or 2 (``escaped=True``).

    With *payloads* a 0x90 packet comes out as its ``(src64, data)`` pair, not as a Frame:
    all that the xbee-sins chain reads of it, one object fewer per SINS frame."""

    format = "xbee"
    sync = b"\x7e"
    header = 3
    integrity = BAD_CHECKSUM

    def __init__(self, escaped: bool = True, max_frame_data: int = 1024,
                 payloads: bool = False) -> None:
        super().__init__()
        self.escaped = escaped
        self.max_frame_data = max_frame_data
        if escaped:
            self._scan = self._scan_escaped
        # the type handed on as a (src64, data) pair; -1, no type: every frame a Frame
        self._payload_type = _RECEIVE_PACKET if payloads else -1

    def _payload(self, offset: int, data: bytes, start: int, size: int) -> bool:
        """Emit the 0x90 packet whose body is ``data[start:start + size]`` as its (src64,
        data) pair (its raw bytes never sliced); False when it is malformed, for the caller
        to accept as any frame."""
        pair = _pick_payload(data, start, size)
        if pair is None:
            return False
        if self._garbage_at >= 0:
            self._close_garbage(offset)
        self.frames += 1
        self._out.append(pair)
        return True

    # API mode 1: the shared length-framed scan
    def _size(self, buf, j: int) -> tuple[int, bool]:
        length = buf[j + 1] << 8 | buf[j + 2]
        return length + 4, 0 < length <= self.max_frame_data

    def _take(self, buf: bytes, j: int, end: int, offset: int) -> bool:
        if sum(buf[j + 3:end]) & 0xFF != 0xFF:
            return False
        ftype = buf[j + 3]
        if ftype != self._payload_type or not self._payload(offset, buf, j + 4, end - j - 5):
            self._accept(offset, buf[j:end], ftype, _XBEE_PARSERS.get(ftype), buf, j + 4,
                         end - j - 5)
        return True

    # API mode 2: a candidate runs to the next bare 7E
    def _scan_escaped(self, buf: bytes, final: bool) -> int:
        base = self._base
        # a bare 7E only ever starts a frame, so each candidate is one piece of a split on 7E
        # (one C call for the whole chunk, instead of two finds and a slice per frame)
        pieces = buf.split(b"\x7e")
        j = len(pieces[0])  # bytes before the first 7E belong to no frame
        if j:
            self._garbage(base, j)
        last = len(pieces) - 1
        unescape, accept, parsers, most = (xbee.unescape_partial, self._accept, _XBEE_PARSERS,
                                           self.max_frame_data)
        payload, payload_type = self._payload, self._payload_type
        for p, seg in enumerate(pieces[1:], 1):
            raw_size = len(seg)
            stop = j + 1 + raw_size
            u, used = unescape(seg)
            got = len(u)
            length = u[0] << 8 | u[1] if got >= 2 else -1
            need = length + 3
            # An error's size is what its judgement read, never "up to the next 7E", which
            # a later chunk may still move: so chunking cannot change it.
            if length == 0 or length > most:
                # judged before waiting, so a false length cannot grow the buffer
                kind, size = BAD_LENGTH, length + 4  # the claimed size, as in API mode 1
            elif got < need:  # (or length < 0)
                more = p == last and not final  # the candidate may still grow
                if used < raw_size and not (more and used == raw_size - 1):
                    # (a 7D that is merely the last byte so far may complete); size: up to
                    # and including the bad pair
                    kind, size = BAD_ESCAPE, min(used + 3, stop - j)
                elif more:
                    return j
                else:
                    kind, size = TRUNCATED, stop - j
            else:
                # the usual case, a frame running exactly to the next 7E, needs no extent count
                end = stop if got == need and used == raw_size else \
                    j + 1 + _raw_extent(seg, need)
                if sum(u[2:need]) & 0xFF == 0xFF:
                    ftype = u[2]
                    if ftype != payload_type or not payload(base + j, u, 3, need - 4):
                        accept(base + j, buf[j:end], ftype, parsers.get(ftype), u, 3, need - 4)
                    if end < stop:  # bytes after the frame, before the next 7E
                        self._garbage(base + end, stop - end)
                    j = stop
                    continue
                kind, size = BAD_CHECKSUM, end - j
            self._error(kind, base + j, size)
            self._garbage(base + j, stop - j)
            j = stop
        return len(buf)


class XBeeSinsChain:
    """What the lab computer does with the coordinator's port: XBee API frames -> the
    payloads of 0x90 packets -> the SINS byte stream of each sending radio -> SINS frames.

    A SINS frame may straddle two 0x90 packets. Each source address has its own SINS
    stream (and offsets within it), at most *max_sources* of them: a new source beyond that
    ends the stream of the least recently heard one as the end of input would (its partial
    frame truncated), reported as an ``evicted`` error and counted; if that source sends
    again, its stream starts afresh at offset 0. Other XBee frames (AT responses, modem
    status, TX status) are passed through, as are the errors of both layers.
    """

    format = "xbee-sins"

    def __init__(self, escaped: bool = True, max_frame_data: int = 1024,
                 max_sources: int = MAX_SOURCES) -> None:
        self.xbee = XBeeDecoder(escaped, max_frame_data, payloads=True)
        self.sins: dict[int, CrcFramedDecoder] = {}  # least recently heard first
        self.max_sources = max_sources
        self.evicted = 0

    def _route(self, events: list) -> list:
        out: list = []
        src, pending = None, []  # a run of 0x90 payloads from one source, fed at once
        for ev in events:
            if type(ev) is tuple:  # a 0x90 packet's (src64, data)
                if ev[0] != src:
                    self._feed_sins(src, pending, out)
                    src, pending = ev[0], []
                pending.append(ev[1])
            else:
                self._feed_sins(src, pending, out)
                src, pending = None, []
                out.append(ev)
        self._feed_sins(src, pending, out)
        return out

    def _feed_sins(self, src: int | None, payloads: list, out: list) -> None:
        if not payloads:
            return
        dec = self.sins.pop(src, None)
        if dec is None:
            if len(self.sins) >= self.max_sources:
                self._evict(out)
            dec = sins_decoder()
            dec.source = src
        self.sins[src] = dec  # now the most recently heard
        out += dec.feed(b"".join(payloads))

    def _evict(self, out: list) -> None:
        src = next(iter(self.sins))
        dec = self.sins.pop(src)
        held = dec.buffered
        out += dec.flush()
        out.append(DecodeError(EVICTED, dec.bytes, held, dec.format, src))
        self.evicted += 1

    def feed(self, data: bytes) -> list:
        return self._route(self.xbee.feed(data))

    def flush(self) -> list:
        out = self._route(self.xbee.flush())
        for dec in self.sins.values():
            out += dec.flush()
        return out

    def decode(self, data: bytes) -> list:
        return self.feed(data) + self.flush()

    @property
    def bytes(self) -> int:
        """Bytes fed (the port's bytes)."""
        return self.xbee.bytes

    @property
    def frames(self) -> int:
        """XBee API frames decoded: the port's own frames, as the other decoders count theirs."""
        return self.xbee.frames

    def summary(self) -> dict:
        return {"format": self.format, "xbee": self.xbee.summary(),
                "sins": {f"{src:016X}": d.summary() for src, d in self.sins.items()},
                "sources_evicted": self.evicted}


__all__ = ["Frame", "DecodeError", "Decoder", "CrcFramedDecoder", "XBeeDecoder", "XBeeSinsChain",
           "sins_decoder", "nanoloc_decoder", "ERROR_KINDS", "plain"]
