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


def _generate(st: c.Struct, only: tuple[str, ...] | None):
    """The source of a flat Struct's parser and what it needs, built from the declaration.

    The parser is generated, as namedtuple and dataclasses generate theirs: a dict display
    (``{"seq": v[0], "words": v[1:12]}``) builds the fields about 3x faster than any loop over
    them. Its source holds only the declaration's field names (as literals) and offsets,
    never a byte of input. With *only*, it returns those fields as a tuple, in that order.
    """
    fmt, names, greedy, exact = _flat_layout(st)
    layout = struct.Struct(fmt)
    fixed = layout.size
    must_equal = exact and greedy is None
    values, k = {}, 0
    for name, n in names:
        values[name] = f"v[{k}]" if n == 1 else f"v[{k}:{k + n}]"
        k += n
    if greedy is not None:
        values[greedy] = f"buf[start + {fixed}:start + size]"  # a slice of bytes is bytes
    if only is None:
        result = "{" + ", ".join(f"{name!r}: {expr}" for name, expr in values.items()) + "}"
    else:
        result = "(" + "".join(f"{values[name]}, " for name in only) + ")"
    check = f"size != {fixed}" if must_equal else f"size < {fixed}"
    source = (f"def parse(buf, start, size):\n"
              f"    if {check}:\n"
              f"        return None\n"
              f"    v = unpack_from(buf, start)\n"
              f"    return {result}\n")
    namespace = {"unpack_from": layout.unpack_from}
    exec(compile(source, f"<fast parser {fmt}>", "exec"), namespace)
    return namespace["parse"], (fixed if must_equal else None)


def compile_flat(st: c.Struct) -> tuple[Callable, int | None]:
    """Compile a flat Struct (fixed-size ints, arrays of ints, fixed Bytes, an optional
    GreedyBytes last, an optional Terminated) into ``parse(buf, start, size) -> dict | None``,
    *buf* a ``bytes`` (a greedy tail is its slice).

    Returns the parser and the exact payload size when the layout has one (Terminated and
    no greedy tail), else None. The parser returns None when *size* does not fit the layout,
    the same frames construct would reject.
    """
    return _generate(st, None)


def picker_for(st: c.Struct, *names: str) -> Callable:
    """``pick(buf, start, size) -> tuple | None``: the fields *names* of a flat Struct, as
    :func:`compile_flat`'s parser would give them, with no dict made (for a reader that
    wants two fields of every frame)."""
    return _generate(st, names)[0]


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
