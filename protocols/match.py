"""What a test awaits on a port's byte stream: bytes, a regex, or a predicate on frames.

A :class:`Match` is made from what the user writes (``b"\\x7e"``, ``re.compile(rb"...")``,
``lambda f: f.type == 0x8B and f.status == 0``); a :class:`Stream` follows one port's bytes
(its declared format's streaming decoder, a bounded history of the last frames) and says
when a match is seen. Both know nothing of where the bytes come from, so a running lab
(emulator.expect) and a replayed recording use the same matchers.

Semantics, as Renode's UART keywords: bytes and regexes search the raw stream from where
the last match ended (a match may straddle chunks; the unmatched tail kept is bounded by
:data:`WINDOW`); a predicate is called on each frame decoded after the last match, as a
:class:`FrameView`.
"""
from __future__ import annotations

import inspect
import re
from collections import deque
from typing import Any, Callable

from . import formats
from .decode import frame_record, printed
from .stream import Frame

WINDOW = 65536  # raw bytes kept for a bytes/regex match (longer patterns never match)
HISTORY = 8  # last frames decoded, kept for a failure's message


class FrameView:
    """A decoded frame as a predicate sees it: ``format``, ``offset``, ``raw``, ``type``,
    ``known``, ``source``, each field of its layout as an attribute (``f.seq``,
    ``f.status``, ``f.words``: raw values, as ``Frame.fields``), and ``record``: the frame
    in engineering units as ``navtwin decode`` prints it (``f.record["gyro_dps"]``).
    A field the frame lacks raises AttributeError, which :class:`Match` reads as no match,
    so one predicate can test the frames of every format on a port."""

    __slots__ = ("frame", "_gyro_range")

    def __init__(self, frame: Frame, gyro_range: int) -> None:
        self.frame = frame
        self._gyro_range = gyro_range

    def __getattr__(self, name: str) -> Any:
        frame = object.__getattribute__(self, "frame")
        if name in Frame.__slots__:
            return getattr(frame, name)
        try:
            return frame.fields[name]
        except KeyError:
            raise AttributeError(f"{frame.format} frame type 0x{frame.type:02X} has no "
                                 f"field {name!r}") from None

    @property
    def record(self) -> dict:
        return frame_record(self.frame, gyro_range=self._gyro_range)

    def __repr__(self) -> str:
        return describe_frame(self.frame, self._gyro_range)


def describe_frame(frame: Frame, gyro_range: int) -> str:
    """One line: the frame's fields in engineering units, as ``navtwin decode`` renders them."""
    rec = printed(frame_record(frame, gyro_range=gyro_range), gyro_range)
    return " ".join(f"{k}={v}" for k, v in rec.items())


def _source(predicate) -> str:
    """A predicate as the test wrote it: its source line, else its name."""
    name = getattr(predicate, "__name__", repr(predicate))
    try:
        line = inspect.getsource(predicate).strip()
    except (OSError, TypeError):
        return name
    return f"{name} ({line})" if len(line) <= 200 else name


class Match:
    """What is awaited: *match* is bytes (found in the raw stream), a compiled regex (searched
    in the raw stream) or a callable on a :class:`FrameView` (true for the awaited frame)."""

    def __init__(self, match: bytes | re.Pattern | Callable[[FrameView], bool]) -> None:
        if isinstance(match, (bytes, bytearray)):
            self.pattern = re.compile(re.escape(bytes(match)))
            self.predicate = None
            self.text = f"bytes {bytes(match)!r}"
        elif isinstance(match, re.Pattern):
            if not isinstance(match.pattern, bytes):
                raise TypeError(f"match: the regex {match.pattern!r} is on str; compile it on "
                                "bytes (re.compile(rb'...')): it searches the raw stream")
            self.pattern, self.predicate = match, None
            self.text = f"regex {match.pattern!r}"
        elif callable(match):
            self.pattern, self.predicate = None, match
            self.text = f"a frame for which {_source(match)} is true"
        else:
            raise TypeError(f"match: {type(match).__name__} is not bytes, a compiled regex or a "
                            "predicate on frames; pass one of those")

    def __str__(self) -> str:
        return self.text

    def frame(self, view: FrameView) -> bool:
        try:
            return bool(self.predicate(view))
        except (AttributeError, KeyError):  # a frame without the field: not the awaited one
            return False


def parse(text: str) -> Match:
    """A :class:`Match` written on a command line (``navtwin emulate --expect PORT:PATTERN``):
    ``hex:7E0005`` bytes, ``re:REGEX`` a regex on the raw stream (its text as Latin-1 bytes:
    ``re:\\x7e\\x00``), or ``FIELD=VALUE,...``: a frame whose fields all equal the values
    (integers in any base, ``type=0x8B,status=0``; else the field's text, ``command=AP``)."""
    kind, _, body = text.partition(":")
    if kind == "hex":
        try:
            return Match(bytes.fromhex(body))
        except ValueError:
            raise ValueError(f"pattern {text!r}: {body!r} is not hex bytes; write e.g. "
                             "hex:7E0005") from None
    if kind == "re":
        try:
            return Match(re.compile(body.encode("latin-1"), re.S))
        except (re.error, UnicodeEncodeError) as e:
            raise ValueError(f"pattern {text!r}: not a byte regex ({e}); write e.g. "
                             "re:\\x7e\\x00.\\x8b") from None
    want = {}
    for item in text.split(","):
        field, eq, value = item.partition("=")
        if not eq or not field.strip():
            raise ValueError(f"pattern {text!r}: write hex:BYTES, re:REGEX or FIELD=VALUE,... "
                             "(e.g. type=0x8B,status=0)")
        try:
            want[field.strip()] = int(value, 0)
        except ValueError:
            want[field.strip()] = value

    def fields(f: FrameView) -> bool:
        return all(_text(getattr(f, k)) == v if isinstance(v, str) else getattr(f, k) == v
                   for k, v in want.items())

    m = Match(fields)
    m.text = f"a frame with {text}"
    return m


def _text(value) -> str:
    return value.decode("latin-1") if isinstance(value, bytes) else str(value)


class Stream:
    """One port's bytes as a client reads them: decoded with the port's *format*
    (protocols.formats; *escaped*: API mode 2), the raw tail since the last match, and the
    last :data:`HISTORY` frames decoded."""

    def __init__(self, format: str, *, escaped: bool = True, gyro_range: int = 300) -> None:
        self.decoder = formats.get(format).make(escaped=escaped)
        self.gyro_range = gyro_range
        self.tail = bytearray()  # raw bytes since the last match (at most WINDOW)
        self.history: deque[Frame] = deque(maxlen=HISTORY)
        self.frames: deque[Frame] = deque()  # decoded since the last match
        self.bytes = 0  # read in all

    def feed(self, data: bytes) -> None:
        self.bytes += len(data)
        self.tail += data
        del self.tail[:-WINDOW]
        for ev in self.decoder.feed(data):
            if isinstance(ev, Frame):
                self.history.append(ev)
                self.frames.append(ev)

    def take(self, match: Match) -> Any:
        """The first match since the last one (a :class:`FrameView`, or a ``re.Match`` on
        the raw tail), consuming the stream up to it; None if none yet."""
        if match.predicate is not None:
            while self.frames:
                view = FrameView(self.frames.popleft(), self.gyro_range)
                if match.frame(view):
                    self.tail.clear()
                    return view
            return None
        found = match.pattern.search(bytes(self.tail))
        if found is not None:
            del self.tail[:found.end()]
            self.frames.clear()
        return found

    def skip(self) -> None:
        """Forget what came so far: later matches look only at bytes fed after this."""
        self.tail.clear()
        self.frames.clear()

    def last_frames(self) -> str:
        """The last frames decoded, one per line, fields in engineering units."""
        if not self.history:
            return "  (no frame decoded)"
        return "\n".join("  " + describe_frame(f, self.gyro_range) for f in self.history)
