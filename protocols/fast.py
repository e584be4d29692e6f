"""Fast parsers derived from the construct declarations.

construct stays the single declaration of every layout. For the flat layouts on the hot
path (the SINS sample, the ranging report, the XBee 0x90 packet) this module turns the
declaration into one precompiled :class:`struct.Struct`, which parses a frame about 30x
faster than construct's interpreter. ``tests/test_fast_path.py`` proves both give the same
fields on the same bytes.
"""
from __future__ import annotations

import struct
from typing import Callable

import construct as c


def plain(obj):
    """construct's parse result as plain Python: dicts, tuples, ints, bytes, str."""
    if isinstance(obj, dict):
        return {k: plain(v) for k, v in obj.items() if not k.startswith("_")}
    if isinstance(obj, list):
        return tuple(plain(v) for v in obj)
    return obj


def _flat_layout(st: c.Struct):
    """(struct format, [(name, count)], greedy name, exact) of a flat Struct."""
    fmt = ">"
    names: list[tuple[str, int]] = []
    greedy = None
    exact = False
    for sub in st.subcons:
        name, inner = (sub.name, sub.subcon) if isinstance(sub, c.Renamed) else (None, sub)
        if greedy is not None and inner is not c.Terminated:
            raise TypeError("GreedyBytes must be the last field")
        if isinstance(inner, c.FormatField):
            fmt += inner.fmtstr[1:]
            names.append((name, 1))
        elif isinstance(inner, c.Array) and isinstance(inner.subcon, c.FormatField) \
                and isinstance(inner.count, int):
            fmt += f"{inner.count}{inner.subcon.fmtstr[1:]}"
            names.append((name, inner.count))
        elif isinstance(inner, c.Bytes) and isinstance(inner.length, int):
            fmt += f"{inner.length}s"
            names.append((name, 1))
        elif inner is c.GreedyBytes:
            greedy = name
        elif inner is c.Terminated:
            exact = True
        else:
            raise TypeError(f"field {name!r} ({type(inner).__name__}) has no fast form")
    return fmt, names, greedy, exact


def packer_for(st: c.Struct) -> Callable[..., bytes]:
    """``pack(*values) -> bytes`` for a flat Struct without a greedy tail: the values in
    declaration order, arrays flattened. The builder twin of :func:`compile_flat`."""
    fmt, _, greedy, _ = _flat_layout(st)
    if greedy is not None:
        raise TypeError("a greedy tail has no fixed packer")
    return struct.Struct(fmt).pack


def compile_flat(st: c.Struct) -> tuple[Callable, int | None]:
    """Compile a flat Struct (fixed-size ints, arrays of ints, fixed Bytes, an optional
    GreedyBytes last, an optional Terminated) into ``parse(buf, start, size) -> dict | None``.

    Returns the parser and the exact payload size when the layout has one (Terminated and
    no greedy tail), else None. The parser returns None when *size* does not fit the layout,
    the same frames construct would reject.
    """
    fmt, names, greedy, exact = _flat_layout(st)
    layout = struct.Struct(fmt)
    fixed = layout.size
    must_equal = exact and greedy is None
    unpack_from = layout.unpack_from
    # where each field sits in the unpacked tuple: an index, or a slice for an array (which so
    # comes out as a tuple); one comprehension per frame, no branch per field
    plan, k = [], 0
    for name, n in names:
        plan.append((name, k if n == 1 else slice(k, k + n)))
        k += n
    plan = tuple(plan)

    def parse(buf, start: int, size: int):
        if size < fixed or (must_equal and size != fixed):
            return None
        values = unpack_from(buf, start)
        out = {name: values[at] for name, at in plan}
        if greedy is not None:
            out[greedy] = bytes(buf[start + fixed:start + size])
        return out

    return parse, (fixed if must_equal else None)


def slow_parser(st) -> Callable:
    """The construct parse of *st* in the same calling convention as a compiled parser."""

    def parse(buf, start: int, size: int):
        try:
            return plain(st.parse(bytes(buf[start:start + size])))
        except c.ConstructError:
            return None

    return parse


def parser_for(st) -> tuple[Callable, int | None]:
    """The fast parser where the layout allows one, else construct's."""
    try:
        return compile_flat(st)
    except TypeError:
        return slow_parser(st), None
