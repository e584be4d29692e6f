"""Two byte streams compared frame by frame: the Python API under ``navtwin diff``.

Each port's bytes (a recording's, or a byte file's) are decoded with the port's own frame
format (protocols.ports: ``frames``) and the two frame lists aligned:

- by sequence number where the frames carry one (a ``seq`` field: SINS frames, nanoLOC
  reports), so a frame missing from one side is "only in A" and does not shift the rest.
  Counters wrap, so the alignment is local: when the frames at the cursors differ in
  ``seq``, the one whose ``seq`` comes again within :data:`WINDOW` frames of the other side
  waits, and the frames before it are only on their side; neither found: the two frames
  pair as one changed frame (its ``seq`` changed);
- otherwise by their index among the frames of their format that have none (XBee API
  frames: by position; in the ``xbee-sins`` chain the SINS frames pair by ``seq`` and the
  coordinator's own frames between them by position).

Both sides of a port are decoded in memory (an hour of the SINS port is 10.8 MB and 360,000
frames): a comparison for tests and CI runs, not a streaming one.

Paired frames with different bytes are reported field by field, raw and in engineering
units where the format gives them (:attr:`navtwin.protocols.formats.Format.labelled`):
``seq 1234 ZGYRO_OUT 0x8123 -> 0x8124 (+0.07326 deg/s)``. A bit flipped inside a CRC-framed
frame breaks its CRC (CRC-16 detects every single-bit error), so that frame is "only in A"
and B has a ``bad_crc`` decode error where it was. Decode errors are matched by kind, size
and the frame before them. Paired frames whose chunk times (the recording's index: device
time, else wall time) differ by more than the tolerance are timing differences.

The first divergence is the first byte at which the two streams differ (or where the
shorter ends), with the device time of the chunk that holds it. Output is bounded: each
list keeps its first ``max_shown`` entries and counts the rest.
"""
from __future__ import annotations

import bisect
import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import formats, ports as lab_ports
from .recording import Recording
from .stream import DecodeError, Frame

WINDOW = 64  # frames looked ahead for a sequence number when the two sides disagree
MAX_SHOWN = 10  # entries of each list kept by default; the rest are counted
TIME_TOLERANCE_S = 0.001  # timing differences of paired frames up to this are not reported


class DiffError(ValueError):
    """Inputs that cannot be compared; one line naming the problem and the fix."""


@dataclass(frozen=True)
class FieldChange:
    """One field of a paired frame: raw values, and in engineering units (``unit``) when
    the format gives them."""

    name: str
    a: Any
    b: Any
    a_value: float | None = None
    b_value: float | None = None
    unit: str = ""

    def text(self) -> str:
        if self.a_value is None or self.b_value is None:
            return f"{self.name} {_raw(self.a)} -> {_raw(self.b)}"
        delta = self.b_value - self.a_value
        return (f"{self.name} 0x{self.a:04X} -> 0x{self.b:04X} "
                f"({delta:+.6g} {self.unit})".rstrip())

    def to_json(self) -> dict:
        out = {"field": self.name, "a": self.a, "b": self.b}
        if self.a_value is not None and self.b_value is not None:
            out.update(a_value=self.a_value, b_value=self.b_value,
                       delta=self.b_value - self.a_value, unit=self.unit)
        return out


def _raw(v) -> str:
    return json.dumps(v) if isinstance(v, (str, list)) else str(v)


@dataclass(frozen=True)
class FrameRef:
    """A frame of one side: its key (its ``seq`` if *by_seq*, else its index among the
    frames of its format without one), type, byte offset and chunk times."""

    key: int
    by_seq: bool
    type: int
    offset: int
    t_device_ns: int | None = None
    t_wall_ns: int | None = None

    def to_json(self) -> dict:
        return {"key": self.key, "by": "seq" if self.by_seq else "position", "type": self.type, "offset": self.offset,
                "t_device_ns": self.t_device_ns, "t_wall_ns": self.t_wall_ns}


@dataclass(frozen=True)
class FrameChange:
    a: FrameRef
    b: FrameRef
    fields: tuple[FieldChange, ...]

    def to_json(self) -> dict:
        return {"a": self.a.to_json(), "b": self.b.to_json(),
                "fields": [f.to_json() for f in self.fields]}


@dataclass(frozen=True)
class Timing:
    a: FrameRef
    b: FrameRef
    clock: str  # t_device_ns or t_wall_ns
    delta_ns: int  # B's time minus A's

    def to_json(self) -> dict:
        return {"a": self.a.to_json(), "b": self.b.to_json(), "clock": self.clock,
                "delta_ns": self.delta_ns}


@dataclass(frozen=True)
class Divergence:
    """The first byte at which the streams differ; ``frame``: A's frame there, if any."""

    offset: int
    t_device_ns: int | None
    frame: FrameRef | None

    def to_json(self) -> dict:
        return {"offset": self.offset, "t_device_ns": self.t_device_ns,
                "frame": self.frame.to_json() if self.frame else None}


@dataclass
class Bounded:
    """The first ``limit`` items of a list and how many there were."""

    limit: int
    items: list = field(default_factory=list)
    count: int = 0

    def add(self, item) -> None:
        self.count += 1
        if len(self.items) < self.limit:
            self.items.append(item)

    def to_json(self) -> dict:
        return {"count": self.count,
                "shown": [i.to_json() if hasattr(i, "to_json") else i for i in self.items]}


@dataclass
class PortDiff:
    """One port's comparison (see the module docstring)."""

    port: str
    format: str | None  # None: a port with no declared format, compared as bytes only
    bytes_a: int
    bytes_b: int
    frames_a: int
    frames_b: int
    first: Divergence | None
    changed: Bounded
    only_a: Bounded
    only_b: Bounded
    errors_a: Bounded  # decode errors only in A
    errors_b: Bounded
    timing: Bounded

    @staticmethod
    def _key(ref: FrameRef) -> str:
        return f"seq {ref.key}" if ref.by_seq else f"frame {ref.key}"

    @property
    def equal(self) -> bool:
        return self.first is None and not self.timing.count

    def summary(self) -> dict:
        return {"bytes_a": self.bytes_a, "bytes_b": self.bytes_b, "frames_a": self.frames_a,
                "frames_b": self.frames_b, "changed": self.changed.count,
                "only_a": self.only_a.count, "only_b": self.only_b.count,
                "errors_only_a": self.errors_a.count, "errors_only_b": self.errors_b.count,
                "timing": self.timing.count}

    def to_json(self) -> dict:
        return {"port": self.port, "format": self.format, "equal": self.equal,
                "summary": self.summary(),
                "first_divergence": self.first.to_json() if self.first else None,
                "changed": self.changed.to_json(), "only_a": self.only_a.to_json(),
                "only_b": self.only_b.to_json(), "errors_only_a": self.errors_a.to_json(),
                "errors_only_b": self.errors_b.to_json(), "timing": self.timing.to_json()}

    def text(self) -> list[str]:
        s = self.summary()
        head = (f"{self.port} ({self.format or 'bytes'}): {'equal' if self.equal else 'differs'}"
                f"; frames A {s['frames_a']} B {s['frames_b']}, bytes A {s['bytes_a']} "
                f"B {s['bytes_b']}; changed {s['changed']}, only in A {s['only_a']}, only in "
                f"B {s['only_b']}, decode errors only in A {s['errors_only_a']} / B "
                f"{s['errors_only_b']}, timing {s['timing']}")
        lines = [head]
        if self.first:
            at = (f" at device time {self.first.t_device_ns / 1e9:.6f} s"
                  if self.first.t_device_ns is not None else "")
            inside = f" ({self._key(self.first.frame)})" if self.first.frame else ""
            lines.append(f"  first divergence: byte {self.first.offset}{at}{inside}")
        for c in self.changed.items:
            lines.append(f"  {self._key(c.a)}: " + "; ".join(f.text() for f in c.fields))
        for side, refs in (("A", self.only_a), ("B", self.only_b)):
            for r in refs.items:
                lines.append(f"  only in {side}: {self._key(r)} at byte {r.offset}")
        for side, errs in (("A", self.errors_a), ("B", self.errors_b)):
            for e in errs.items:
                lines.append(f"  decode error only in {side}: {e['error']} at byte "
                             f"{e['offset']} ({e['size']} bytes)")
        for t in self.timing.items:
            lines.append(f"  timing: {self._key(t.a)} {t.clock} "
                         f"{t.delta_ns / 1e6:+.3f} ms")
        for name, b in (("changed frames", self.changed), ("frames only in A", self.only_a),
                        ("frames only in B", self.only_b), ("errors only in A", self.errors_a),
                        ("errors only in B", self.errors_b), ("timing differences", self.timing)):
            if b.count > len(b.items):
                lines.append(f"  ... and {b.count - len(b.items)} more {name}")
        return lines


@dataclass
class Diff:
    """The comparison of two recordings (or two byte streams): per port, and the ports only
    one side has."""

    a: str
    b: str
    ports: dict[str, PortDiff]
    ports_only_a: list[str] = field(default_factory=list)
    ports_only_b: list[str] = field(default_factory=list)

    @property
    def equal(self) -> bool:
        return (not self.ports_only_a and not self.ports_only_b
                and all(p.equal for p in self.ports.values()))

    def to_json(self) -> dict:
        return {"a": self.a, "b": self.b, "equal": self.equal,
                "ports_only_a": self.ports_only_a, "ports_only_b": self.ports_only_b,
                "ports": {n: p.to_json() for n, p in self.ports.items()}}

    def text(self) -> str:
        lines = [f"A {self.a}", f"B {self.b}"]
        lines += [f"port only in A: {p}" for p in self.ports_only_a]
        lines += [f"port only in B: {p}" for p in self.ports_only_b]
        for p in self.ports.values():
            lines += p.text()
        lines.append("equal" if self.equal else "different")
        return "\n".join(lines) + "\n"


@dataclass
class _Side:
    """One side of a port: its bytes, its chunk index and its decoded frames and errors."""

    data: bytes
    starts: list[int]  # chunk offsets, ascending
    t_device: list[int | None]
    t_wall: list[int | None]
    frames: list[Frame] = field(default_factory=list)
    errors: list[DecodeError] = field(default_factory=list)
    keys: list[tuple] = field(default_factory=list)  # each frame's, for the alignment

    def times(self, offset: int) -> tuple[int | None, int | None]:
        i = bisect.bisect_right(self.starts, offset) - 1
        return (self.t_device[i], self.t_wall[i]) if i >= 0 else (None, None)

    def ref(self, index: int) -> FrameRef:
        f, (_, by, key) = self.frames[index], self.keys[index]
        return FrameRef(key, by == "seq", f.type, f.offset, *self.times(f.offset))


def _decode(side: _Side, fmt: formats.Format, escaped: bool) -> None:
    """Decode the side's bytes; each frame's key is ``((format, type), "seq", seq)`` where its
    layout has a ``seq`` (a SINS sample and the magnetometer frame read with it share one),
    else ``(format, "n", its index among that format's frames without one)`` (a chain passes
    the coordinator's own frames between the SINS frames it carries)."""
    dec = fmt.make(escaped=escaped)
    unsequenced: Counter = Counter()
    for ev in dec.feed(side.data) + dec.flush():
        if not isinstance(ev, Frame):
            side.errors.append(ev)
            continue
        side.frames.append(ev)
        if ev.known and "seq" in ev.fields:
            side.keys.append(((ev.format, ev.type), "seq", ev.fields["seq"]))
        else:
            side.keys.append((ev.format, "n", unsequenced[ev.format]))
            unsequenced[ev.format] += 1


def _fields(frame: Frame, gyro_range: int) -> dict[str, tuple]:
    """name -> (raw, value in units or None, unit) of a frame's fields, as the format of its
    layout gives them (a chain's frames are another format's: xbee-sins gives SINS frames)."""
    if not frame.known:
        return {"type": (frame.type, None, ""), "payload": (frame.fields["payload"].hex().upper(),
                                                            None, "")}
    fmt = formats.get(frame.format)
    if fmt.labelled is not None:
        return fmt.label(frame, gyro_range)
    out: dict[str, tuple] = {}
    for k, v in fmt.render(frame, gyro_range).items():
        for i, x in enumerate(v) if isinstance(v, list) else [(None, v)]:
            out[k if i is None else f"{k}[{i}]"] = (x, None, "")
    return out


def _changes(fa: Frame, fb: Frame, gyro_range: int) -> tuple[FieldChange, ...]:
    if fa.type != fb.type or fa.known != fb.known:
        return (FieldChange("type", fa.type, fb.type),)
    a, b = _fields(fa, gyro_range), _fields(fb, gyro_range)
    out = []
    for name in dict.fromkeys([*a, *b]):
        ra, va, unit = a.get(name, (None, None, ""))
        rb, vb, _ = b.get(name, (None, None, ""))
        if ra != rb:
            out.append(FieldChange(name, ra, rb, va, vb, unit))
    return tuple(out)


def _align(ka: list, kb: list) -> list[tuple[int | None, int | None]]:
    """Pairs of indices (None: only on the other side); see the module docstring."""
    out, i, j = [], 0, 0
    while i < len(ka) and j < len(kb):
        if ka[i] == kb[j]:
            out.append((i, j))
            i, j = i + 1, j + 1
            continue
        in_b = next((m for m in range(j + 1, min(j + 1 + WINDOW, len(kb))) if kb[m] == ka[i]),
                    None)
        in_a = next((k for k in range(i + 1, min(i + 1 + WINDOW, len(ka))) if ka[k] == kb[j]),
                    None)
        if in_a is None and in_b is None:
            out.append((i, j))
            i, j = i + 1, j + 1
        elif in_b is None or (in_a is not None and in_a - i <= in_b - j):
            out += [(k, None) for k in range(i, in_a)]
            i = in_a
        else:
            out += [(None, m) for m in range(j, in_b)]
            j = in_b
    out += [(k, None) for k in range(i, len(ka))] + [(None, m) for m in range(j, len(kb))]
    return out


def _first_byte(a: bytes, b: bytes) -> int | None:
    if a == b:
        return None
    n = min(len(a), len(b))
    lo, hi = 0, n  # the first differing byte by halving (bytes compare in C)
    while lo < hi:
        mid = (lo + hi) // 2
        if a[lo:mid + 1] == b[lo:mid + 1]:
            lo = mid + 1
        else:
            hi = mid
    return lo


def _error_keys(side: _Side) -> list[tuple]:
    """Each decode error's (kind, size, key of the frame before it), in order."""
    starts = [f.offset for f in side.frames]
    keys = []
    for e in side.errors:
        before = bisect.bisect_left(starts, e.offset) - 1
        keys.append((e.kind, e.size, side.keys[before] if before >= 0 else None))
    return keys


def _compare(port: str, fmt: formats.Format | None, a: _Side, b: _Side, *, escaped_a: bool,
             escaped_b: bool, gyro_range: int, tolerance_ns: int, max_shown: int) -> PortDiff:
    def bounded() -> Bounded:
        return Bounded(max_shown)
    changed, only_a, only_b, err_a, err_b, timing = (bounded() for _ in range(6))
    first_at = _first_byte(a.data, b.data)
    if fmt is not None:
        _decode(a, fmt, escaped_a)
        _decode(b, fmt, escaped_b)
    for i, j in _align(a.keys, b.keys):
        if j is None:
            only_a.add(a.ref(i))
        elif i is None:
            only_b.add(b.ref(j))
        else:
            ra, rb = a.ref(i), b.ref(j)
            if a.frames[i].raw != b.frames[j].raw:
                changed.add(FrameChange(ra, rb, _changes(a.frames[i], b.frames[j], gyro_range)))
            for clock in ("t_device_ns", "t_wall_ns"):
                ta, tb = getattr(ra, clock), getattr(rb, clock)
                if ta is not None and tb is not None:
                    if abs(tb - ta) > tolerance_ns:
                        timing.add(Timing(ra, rb, clock, tb - ta))
                    break
    ka, kb = _error_keys(a), _error_keys(b)
    for shown, side, keys, other in ((err_a, a, ka, kb), (err_b, b, kb, ka)):
        extra = Counter(keys) - Counter(other)
        for e, k in zip(side.errors, keys):
            if extra[k] > 0:
                extra[k] -= 1
                shown.add({"error": e.kind, "offset": e.offset, "size": e.size})
    first = None
    if first_at is not None:
        t_dev = a.times(first_at)[0] if first_at < len(a.data) else b.times(first_at)[0]
        at = bisect.bisect_right([f.offset for f in a.frames], first_at) - 1
        inside = at >= 0 and first_at < a.frames[at].offset + len(a.frames[at].raw)
        first = Divergence(first_at, t_dev, a.ref(at) if inside else None)
    return PortDiff(port, fmt.name if fmt else None, len(a.data), len(b.data), len(a.frames),
                    len(b.frames), first, changed, only_a, only_b, err_a, err_b, timing)


def _recording_side(rec: Recording, port: str) -> _Side:
    chunks = list(rec.chunks(port))
    return _Side(b"".join(c.data for c in chunks), [c.offset for c in chunks],
                 [c.t_device_ns for c in chunks], [c.t_wall_ns for c in chunks])


def _escaped(rec: Recording, port: str) -> bool:
    return lab_ports.escaped(rec.meta["ports"].get(port, {}))


def _port_format(port: str) -> formats.Format | None:
    """The port's own frame format, or None for a port navtwin does not declare."""
    return formats.get(lab_ports.get(port).frame_format) if port in lab_ports.PORTS else None


def diff_recordings(a: str | Path | Recording, b: str | Path | Recording, *,
                    ports: list[str] | None = None, time_tolerance_s: float = TIME_TOLERANCE_S,
                    gyro_range: int = 300, max_shown: int = MAX_SHOWN) -> Diff:
    """Compare two recording directories port by port (*ports*: only these, each of which
    one of them must have); raises :class:`navtwin.protocols.recording.RecordingError` for
    a directory that is not a recording."""
    ra = a if isinstance(a, Recording) else Recording(a)
    rb = b if isinstance(b, Recording) else Recording(b)
    names = [p for p in lab_ports.names() if p in ra.ports or p in rb.ports]
    names += sorted((set(ra.ports) | set(rb.ports)) - set(names))
    if ports is not None:
        unknown = [p for p in ports if p not in names]
        if unknown:
            raise DiffError(f"port: {', '.join(unknown)} in neither recording (they have "
                            f"{', '.join(names)})")
        names = [p for p in names if p in ports]
    out = Diff(str(ra.directory), str(rb.directory), {})
    for p in names:
        if p not in rb.ports:
            out.ports_only_a.append(p)
        elif p not in ra.ports:
            out.ports_only_b.append(p)
        else:
            out.ports[p] = _compare(p, _port_format(p), _recording_side(ra, p),
                                    _recording_side(rb, p), escaped_a=_escaped(ra, p),
                                    escaped_b=_escaped(rb, p), gyro_range=gyro_range,
                                    tolerance_ns=round(time_tolerance_s * 1e9),
                                    max_shown=max_shown)
    return out


def diff_bytes(a: bytes, b: bytes, format: str, *, escaped: bool = True, gyro_range: int = 300,
               max_shown: int = MAX_SHOWN, names: tuple[str, str] = ("A", "B")) -> Diff:
    """Compare two byte streams of wire format *format* (no chunk index, so no times); the
    result has one port named after the format."""
    fmt = formats.get(format)
    sides = [_Side(data, [], [], []) for data in (a, b)]
    return Diff(*names, {format: _compare(format, fmt, *sides, escaped_a=escaped,
                                          escaped_b=escaped, gyro_range=gyro_range,
                                          tolerance_ns=0, max_shown=max_shown)})
