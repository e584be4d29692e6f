"""Fast parsers derived from the construct declarations.

construct stays the single declaration of every layout. For the flat layouts on the hot
path (the SINS sample, the ranging report, the XBee 0x90 packet) this module turns the
declaration into one precompiled :class:`struct.Struct`, which parses a frame about 30x
faster than construct's interpreter. ``tests/protocols/test_properties.py`` proves both give
the same fields on the same bytes.

The builders' twins: :func:`packer_for` packs one frame's payload with the same
``struct.Struct``, and :func:`rows_packer` a block of them as the rows of one numpy array,
the declaration made a numpy structured type (the world makes a second's frames at once:
emulator.board, emulator.nanoloc, emulator.radio).
"""
from __future__ import annotations

import operator
import struct
import sys
from typing import Callable

import construct as c
import numpy as np


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


def _getter(items: list) -> Callable[[tuple], tuple]:
    """``get(v) -> tuple`` of v[item] for each item (an index or a slice), in C:
    :func:`operator.itemgetter`, which gives a bare value for one item, made to give a tuple."""
    if len(items) == 1:
        (item,) = items
        return lambda v: (v[item],)
    return operator.itemgetter(*items) if items else lambda v: ()


def _generate(st: c.Struct, only: tuple[str, ...] | None):
    """A flat Struct's parser and its exact size, built from the declaration.

    One precompiled ``unpack_from`` gives the flat values; an ``itemgetter`` of each field's
    index (a scalar) or slice (an array) regroups them in declaration order, and ``dict(zip())``
    names them: each step one C call, no Python loop over the fields (3x faster than one). A
    greedy tail, always last, is the frame's remaining slice. With *only*, those fields as a
    tuple, in that order (a greedy tail among them last).
    """
    fmt, names, greedy, exact = _flat_layout(st)
    layout = struct.Struct(fmt)
    unpack_from, fixed = layout.unpack_from, layout.size
    must_equal = exact and greedy is None
    items, k = {}, 0
    for name, n in names:
        items[name] = k if n == 1 else slice(k, k + n)
        k += n
    if only is None:
        wanted, tail = list(items), greedy is not None
    else:
        tail = greedy is not None and only[-1:] == (greedy,)
        wanted = list(only[:-1] if tail else only)
        if not set(wanted) <= set(items):
            raise TypeError(f"pick {only}: fields of the layout, a greedy tail last")
    get = _getter([items[n] for n in wanted])

    if only is not None:
        if tail and len(wanted) == 1:  # 0x90's (src64, data): the chain's pick, per packet
            (item,) = (items[n] for n in wanted)

            def parse(buf, start, size):
                if size < fixed:
                    return None
                return unpack_from(buf, start)[item], buf[start + fixed:start + size]
        elif tail:
            def parse(buf, start, size):
                if size < fixed:
                    return None
                return get(unpack_from(buf, start)) + (buf[start + fixed:start + size],)
        else:
            def parse(buf, start, size):
                return None if size < fixed else get(unpack_from(buf, start))
        return parse, None

    keys = tuple(wanted)
    name = _namer(keys, [items[n] for n in wanted], get)
    if tail:
        def parse(buf, start, size):
            if size < fixed:
                return None
            fields = name(unpack_from(buf, start))
            fields[greedy] = buf[start + fixed:start + size]  # a slice of bytes is bytes
            return fields
    elif must_equal:
        def parse(buf, start, size):
            return None if size != fixed else name(unpack_from(buf, start))
    else:
        def parse(buf, start, size):
            return None if size < fixed else name(unpack_from(buf, start))
    return parse, (fixed if must_equal else None)


def _namer(keys: tuple, items: list, get: Callable) -> Callable[[tuple], dict]:
    """``name(v) -> dict`` of the fields: a dict display for the two-field layouts (the SINS
    sample, seq and words: 100 a second per vehicle, 0.39 us against dict(zip())'s 0.64),
    else ``dict(zip(keys, get(v)))``."""
    if len(keys) == 2:
        (k0, k1), (i0, i1) = keys, items
        return lambda v: {k0: v[i0], k1: v[i1]}
    return lambda v: dict(zip(keys, get(v)))


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


#: numpy's type of each struct format character of a FormatField
_NUMPY_TYPES = {"B": "u1", "b": "i1", "H": "u2", "h": "i2", "I": "u4", "i": "i4", "L": "u4",
                "l": "i4", "Q": "u8", "q": "i8", "e": "f2", "f": "f4", "d": "f8"}


def _numpy_type(field: c.FormatField) -> np.dtype:
    order, code = field.fmtstr[0], field.fmtstr[1:]
    if code not in _NUMPY_TYPES or order not in "<>=":
        raise TypeError(f"format {field.fmtstr!r} has no numpy form")
    return np.dtype(order.replace("=", "<" if sys.byteorder == "little" else ">") + _NUMPY_TYPES[code])


def _limits(t: np.dtype):
    """The range an integer field's values must lie in (None: a float's)."""
    return np.iinfo(t) if t.kind in "iu" else None


def _row_fields(st: c.Struct, tail: bool):
    """(numpy structured type, [(name, dims, limits)] of the fields a packer takes, {name:
    Const bytes}) of a flat Struct; with *tail*, a GreedyBytes last is allowed and left out."""
    fields, given, fixed = [], [], {}
    for i, sub in enumerate(st.subcons):
        name, inner = (sub.name, sub.subcon) if isinstance(sub, c.Renamed) else (None, sub)
        key = name or f"_{i}"
        if isinstance(inner, c.Const) and isinstance(inner.value, bytes):
            fields.append((key, np.uint8, (len(inner.value),)))
            fixed[key] = np.frombuffer(inner.value, dtype=np.uint8)
        elif isinstance(inner, c.FormatField):
            fields.append((key, _numpy_type(inner)))
            given.append((key, 0, _limits(fields[-1][1])))
        elif isinstance(inner, c.Array) and isinstance(inner.subcon, c.FormatField) \
                and isinstance(inner.count, int):
            fields.append((key, _numpy_type(inner.subcon), (inner.count,)))
            given.append((key, 1, _limits(fields[-1][1])))
        elif tail and inner is c.GreedyBytes and i == len(st.subcons) - 1:
            break
        elif inner is not c.Terminated:
            raise TypeError(f"field {name!r} ({type(inner).__name__}) has no row form")
    return np.dtype(fields), given, fixed


def rows_layout(st: c.Struct) -> np.dtype:
    """The numpy structured type of a flat Struct's fixed fields, in declaration order (a
    GreedyBytes last, a packet's data, is left out): ``rows.view(rows_layout(st))`` reads n
    payloads, one an (n, itemsize) uint8 row, as :func:`compile_flat`'s parser reads one."""
    return _row_fields(st, tail=True)[0]


def rows_packer(st: c.Struct) -> Callable[..., np.ndarray]:
    """``pack(*columns) -> (n, size) uint8``: n payloads of a flat Struct at once, one row
    each, equal to n calls of :func:`packer_for`'s packer (the block builder of the frames a
    device writes a second at a time). The columns are the fields' values in declaration
    order: per row, an (n,) array for a field, an (n, count) array for an Array; or one value
    every row shares (an int, a (count,) array); at least one column per row. A Const field
    is its declared bytes and takes no column. The layout is a numpy structured type made
    from the declaration (each field's width and byte order), so the bytes are numpy's
    assignment into it; a value outside its field's range is refused, as ``struct.pack``
    refuses it."""
    layout, given, fixed = _row_fields(st, tail=False)

    def pack(*columns) -> np.ndarray:
        if len(columns) != len(given):
            raise TypeError(f"{len(given)} columns ({', '.join(k for k, _, _ in given)}), "
                            f"not {len(columns)}")
        columns = [np.asarray(v) for v in columns]
        n = next((len(v) for v, (_, dims, _) in zip(columns, given) if v.ndim > dims), None)
        if n is None:
            raise TypeError("no column has a value per row: give one an array of n rows")
        rows = np.empty(n, dtype=layout)
        for key, value in fixed.items():
            rows[key] = value
        for (key, _, limits), column in zip(given, columns):
            if limits is not None and column.size and (column.min() < limits.min
                                                       or column.max() > limits.max):
                raise ValueError(f"field {key!r}: a value outside {limits.min}..{limits.max}")
            rows[key] = column
        return rows.view(np.uint8).reshape(n, layout.itemsize)

    return pack


def frames_of(rows: np.ndarray) -> list[bytes]:
    """Each row of an (n, size) uint8 block as its own ``bytes`` (the frames an event
    carries): one copy of the block, then a slice per frame."""
    size = rows.shape[1]
    block = rows.tobytes()
    return [block[i:i + size] for i in range(0, len(block), size)]
