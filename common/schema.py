"""Typed TOML tables declared as frozen dataclasses: validation, TOML output, docs table.

A table is a dataclass whose fields carry their unit, meaning and checks (:func:`key`).
:func:`build` turns a parsed TOML dict into the dataclass and raises :class:`Invalid` with
ONE line naming the key, the problem and the fix (:func:`plain` gives the dict back);
:func:`dump` writes it back as TOML (every key, defaults included, so the text is the
scenario exactly as run); :func:`rows` lists every key for the documentation. Field types
understood: bool, int, float, str, dict (a table passed on as it is), a map keyed by id
(``dict[int, float]`` with ``key(..., ids=("anchor", (1, 254)))``: ``{1 = 0.3, 2 = 0.25}``,
the field's checks applied to each value), ``float | None`` (optional), ``Table | None``
(an optional table: absent from the TOML, and from the scenario written back, unless
given), fixed and variable tuples of numbers, tuples of points, a matrix (a fixed tuple of
fixed tuples), a nested table (dataclass) and an array of tables
(``tuple[Table, ...]``; a class attribute ``KINDS``, a protocols.plugins.Registry, maps a
``kind`` key to one dataclass per kind). :func:`value` checks one value alike (a
command-line number, a figure in a file).
"""
from __future__ import annotations

import dataclasses
import difflib
import json
import math
import types
import typing
from dataclasses import MISSING, dataclass
from typing import Any, Callable

from navtwin.common.limits import finite, span
from navtwin.common.limits import show as _num


class Invalid(ValueError):
    """A validation problem: *where* (e.g. ``[trajectory] speed_m_s``) and a one-line text."""

    def __init__(self, where: str, problem: str) -> None:
        super().__init__(f"{where} {problem}".strip())
        self.where = where
        self.problem = problem


@dataclass(frozen=True)
class Check:
    """``ok(value)`` must hold, else ``<key> <must> (got <value>); <fix>``."""

    ok: Callable[[Any], bool]
    must: str
    fix: str


def positive(fix: str | None = None, hi: float = math.inf) -> Check:
    """> 0 and <= *hi*: the upper bound keeps finite but absurd values (1e308 s) out of the
    emulator's integer nanoseconds and its noise draws."""
    return Check(lambda v: 0 < v <= hi, f"must be {span(0, hi, above=True)}",
                 fix or ("set a positive value" if hi == math.inf
                         else f"use a value above 0 and up to {_num(hi)}"))


def non_negative(fix: str | None = None, hi: float = math.inf) -> Check:
    return between(0, hi, fix or "set 0 or a positive value")


def between(lo: float, hi: float, fix: str | None = None) -> Check:
    return Check(lambda v: lo <= v <= hi, f"must be {span(lo, hi)}",
                 fix or f"use a value from {_num(lo)} to {_num(hi)}")


def counts(lo: int, hi: int, example: str) -> Check:
    """A comma-separated list of whole numbers in [lo, hi] (a benchmark's sizes, as text)."""
    def ok(text: str) -> bool:
        try:
            return all(lo <= int(v) <= hi for v in text.split(","))
        except ValueError:
            return False
    return Check(ok, f"must be counts {lo}..{hi}, comma-separated", f"use e.g. {example}")


def one_of(*allowed, fix: str | None = None) -> Check:
    names = ", ".join(repr(a) if isinstance(a, str) else _num(a) for a in allowed)
    return Check(lambda v: v in allowed, f"must be one of {names}", fix or f"use one of {names}")


def boolean(fix: str = "write true or false") -> Check:
    """A TOML boolean (its rule stated in the docs' key tables like every other key's)."""
    return Check(lambda v: isinstance(v, bool), "must be true or false", fix)


def each(check: Check) -> Check:
    """Apply *check* to every element of a tuple value."""
    return Check(lambda v: all(check.ok(x) for x in v), f"elements {check.must}", check.fix)


REQUIRED = MISSING


def key(default: Any, unit: str, doc: str, *checks: Check, hex: int = 0,
        ids: tuple[str, tuple[int, int]] | None = None) -> Any:
    """A dataclass field with its unit, meaning and checks (*default* REQUIRED = required);
    an integer with *hex* digits is written in hex; a map's keys are *ids* (noun, (lo, hi)),
    its checks apply to each value."""
    meta = {"unit": unit, "doc": doc, "checks": checks, "hex": hex, "ids": ids}
    if isinstance(default, (list, dict)):
        raise TypeError("use tuples for defaults")
    return dataclasses.field(default=default, metadata=meta)


def takes(settings: type) -> Callable:
    """Declare the settings of a function as a table class of :func:`key` fields, its
    ``Settings`` attribute: ``navtwin bench NAME --setting value`` builds them (checked as a
    table is) and calls ``fn(quick, settings)``."""
    def mark(fn: Callable) -> Callable:
        fn.Settings = settings
        return fn
    return mark


# -- building ----------------------------------------------------------------------------
#: how much of a wrong value a message shows: list elements, nesting, string characters
SHOW_ITEMS, SHOW_DEPTH, SHOW_CHARS = 8, 3, 40


def _describe(value: Any, depth: int = 0) -> str:
    """*value* as a message shows it: short, whatever its size or depth (a control request
    may nest lists as deep as JSON allows)."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        if depth >= SHOW_DEPTH:
            return "[...]"
        shown = [_describe(v, depth + 1) for v in value[:SHOW_ITEMS]]
        return "[" + ", ".join(shown + ["..."] * (len(value) > SHOW_ITEMS)) + "]"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, int) and not isinstance(value, bool) and \
            len(digits := str(abs(value))) > 20:
        return f"an integer of {len(digits)} digits"
    if isinstance(value, str):
        return repr(value[:SHOW_CHARS]) + ("..." if len(value) > SHOW_CHARS else "")
    return str(value)


def _is_table(tp) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _is_tables(tp) -> bool:
    """An array of tables, ``tuple[Table, ...]``."""
    args = typing.get_args(tp)
    return typing.get_origin(tp) is tuple and bool(args) and _is_table(args[0])


def _example(tp) -> tuple[str, str]:
    """(what a value of type *tp* is, how one is written) for error messages."""
    if tp is float:
        return "a number", "0.5"
    if tp is int:
        return "an integer", "3"
    if tp is bool:
        return "true or false", "true"
    if tp is str:
        return "a string", '"text"'
    if tp is dict:  # a table kept as it is, for its reader to build (a live fault's settings)
        return "a table", '{"kind": "bit_errors"}'
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is dict:
        return "a table of id = value", "{1 = 0.3, 2 = 0.25}"
    if origin in (typing.Union, types.UnionType):
        return _example(next(a for a in args if a is not type(None)))
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        if typing.get_origin(args[0]) is tuple:
            return "a list of points", "[[0.0, 0.0], [1.0, 2.0]]"
        return "a list", "[1.0, 2.0]"
    if origin is tuple and typing.get_origin(args[0]) is tuple:  # a matrix
        row = "[" + ", ".join(["1.0"] * len(typing.get_args(args[0]))) + "]"
        return (f"a list of {len(args)} rows of {len(typing.get_args(args[0]))} numbers",
                "[" + ", ".join([row] * len(args)) + "]")
    if origin is tuple:
        return f"a list of {len(args)} numbers", "[" + ", ".join(["1.0"] * len(args)) + "]"
    raise TypeError(f"unsupported field type {tp!r}")


def _convert(value: Any, tp, at: str) -> Any:
    """*value* from TOML as type *tp*, or Invalid naming *at*."""
    what, like = _example(tp)
    wrong = Invalid(at, f"must be {what} (got {_describe(value)}); write it like {like}")
    if tp is bool:
        if not isinstance(value, bool):
            raise wrong
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise wrong
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise wrong
        if not finite(value):
            raise Invalid(at, f"must be a finite number (got {_describe(value)}); write a finite number")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise wrong
        return value
    if tp is dict:
        if not isinstance(value, dict):
            raise wrong
        return value
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return _convert(value, next(a for a in args if a is not type(None)), at)
    if not isinstance(value, list):
        raise wrong
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(v, args[0], f"{at}[{i}]") for i, v in enumerate(value))
    if len(value) != len(args):
        raise wrong
    return tuple(_convert(v, a, f"{at}[{i}]") for i, (v, a) in enumerate(zip(value, args)))


def _checked(v: Any, at: str, meta) -> Any:
    """*v* if it passes the checks of *meta* (a key's), else Invalid naming *at*."""
    for check in meta.get("checks", ()):
        if v is not None and not check.ok(v):
            unit = meta.get("unit", "")
            got = _describe(v) + (f" {unit}" if unit and not isinstance(v, tuple) else "")
            raise Invalid(at, f"{check.must} (got {got}); {check.fix}")
    return v


def _map(value: Any, tp, at: str, meta) -> dict:
    """A table keyed by id (``{1 = 0.3}``, TOML keys are strings): each key an id of
    ``meta["ids"]``, each value of the map's value type, passing the key's checks."""
    noun, (lo, hi) = meta["ids"]
    if not isinstance(value, dict):
        raise Invalid(at, f"must be a table of {noun} id = value like {{1 = 0.3, 2 = 0.25}} "
                          f"(got {_describe(value)}); write it so")
    _, vtype = typing.get_args(tp)
    out = {}
    for k, v in value.items():
        i = int(k) if k.isdigit() and len(k) < 5 else None
        if i is None or not lo <= i <= hi:
            raise Invalid(at, f"names {noun} {k[:SHOW_CHARS]!r}, which is not an {noun} id "
                              f"({lo}..{hi}); name each {noun} by its id")
        out[i] = _checked(_convert(v, vtype, f"{at} {i}"), f"{at} {i}", meta)
    return out


def value(raw: Any, tp, where: str, *checks: Check, unit: str = "") -> Any:
    """One value outside a table (a command-line number, a figure read from a file) as type
    *tp*, checked as a key is; Invalid naming *where*."""
    return _checked(_convert(raw, tp, where), where, {"checks": checks, "unit": unit})


KeyPath = tuple  # of (table name, 1-based entry number or 0)


def where(path: KeyPath, name: str = "") -> str:
    """How a key is named in messages: ``duration_s``, ``[trajectory] speed_m_s``,
    ``[[anchors]] #2 x``."""
    if not path:
        return name or "top level"
    label = ".".join(n for n, _ in path)
    entry = path[-1][1]
    table = f"[[{label}]] #{entry}" if entry else f"[{label}]"
    return f"{table} {name}".strip()


def _how_to_add(path: KeyPath, name: str, tp, meta) -> str:
    label = ".".join([n for n, _ in path] + [name])
    if _is_table(tp):
        return f"add a [{label}] table"
    args = typing.get_args(tp)
    if typing.get_origin(tp) is tuple and args and _is_table(args[0]):
        return f"add [[{label}]] tables"
    what = ", ".join(x for x in (meta.get("doc", "").split(";")[0], meta.get("unit", "")) if x)
    return f"add {name} = <{what or _example(tp)[0]}>"


def _unknown(at: str, name: str, known: list[str]) -> Invalid:
    name = name[:SHOW_CHARS]  # a key of any length (JSON's) is matched and shown by its start
    near = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    hint = f"did you mean '{near[0]}'?" if near else "known keys: " + ", ".join(known)
    return Invalid(at, f"has an unknown key '{name}'; {hint}")


def build(cls, data: Any, path: KeyPath = ()):
    """An instance of table class *cls* from TOML *data* found at *path*."""
    if not isinstance(data, dict):
        raise Invalid(where(path), f"must be a table (got {_describe(data)}); write it as a table")
    kinds = getattr(cls, "KINDS", None)
    if kinds is not None:
        kind = data.get("kind")
        if not isinstance(kind, str) or kind not in kinds:
            names = ", ".join(repr(k) for k in kinds.names())
            raise Invalid(where(path, "kind"), f"must be one of {names} (got {_describe(kind)}); "
                                               f"set kind to one of {names}")
        cls = kinds.get(kind)
        data = {k: v for k, v in data.items() if k != "kind"}
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for name in data:
        if name not in fields:
            raise _unknown(where(path), name, list(fields) + (["kind"] if kinds else []))
    values = {}
    for name, f in fields.items():
        at = where(path, name)
        tp = hints[name]
        if name not in data:
            if f.default is MISSING:
                raise Invalid(at, "is missing; " + _how_to_add(path, name, tp, f.metadata))
            continue
        raw = data[name]
        origin, args = typing.get_origin(tp), typing.get_args(tp)
        if origin in (typing.Union, types.UnionType):  # optional: what it is when given
            tp = next(a for a in args if a is not type(None))
            origin, args = typing.get_origin(tp), typing.get_args(tp)
        if _is_table(tp):
            values[name] = build(tp, raw, path + ((name, 0),))
            continue
        if origin is dict:
            values[name] = _map(raw, tp, at, f.metadata)
            continue
        if origin is tuple and args and _is_table(args[0]):
            if not isinstance(raw, list):
                raise Invalid(at, f"must be an array of tables (got {_describe(raw)}); "
                                  f"write each entry as [[{name}]]")
            values[name] = tuple(build(args[0], item, path + ((name, i + 1),))
                                 for i, item in enumerate(raw))
            continue
        values[name] = _checked(_convert(raw, tp, at), at, f.metadata)
    try:
        return cls(**values)
    except Invalid as e:  # a cross-field check in __post_init__ names a key of this table
        raise Invalid(where(path, e.where), e.problem) from None


def kind_of(obj) -> str | None:
    """The ``kind`` value of an array-of-tables entry whose class is one of a KINDS registry."""
    return getattr(type(obj), "KIND", None)


# -- TOML output -------------------------------------------------------------------------
def _scalar(v: Any, hex: int = 0) -> str:
    if hex:
        return f"0x{v:0{hex}X}"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):  # JSON string escapes are TOML basic-string escapes
        return json.dumps(v).replace("\x7f", "\\u007f")
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def dump_document(doc: dict, path: str = "") -> str:
    """TOML text of a document of plain data (tables as dicts, arrays of tables as lists of
    dicts, as :func:`plain` and ``tomllib`` give them): ``tomllib.loads`` reads it back equal."""
    def bare(k: str) -> str:
        return k if k and all(c.isascii() and (c.isalnum() or c in "_-") for c in k) else _scalar(k)

    def sections(table: dict, at: str, header: str) -> list[str]:
        keys, tables = [], []
        for k, v in table.items():
            sub = f"{at}.{bare(k)}" if at else bare(k)
            if isinstance(v, dict):
                tables += sections(v, sub, f"\n[{sub}]")
            elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
                for item in v:
                    tables += sections(item, sub, f"\n[[{sub}]]")
            else:
                keys.append(f"{bare(k)} = {_scalar(v)}")
        head = [header] if header and (keys or header.startswith("\n[[")) else []
        return head + keys + tables
    return "\n".join(sections(doc, path, "")).lstrip("\n") + "\n"


def dump(obj, path: str = "") -> str:
    """TOML text of table *obj* (a dataclass instance) and its sub-tables, every key written."""
    return "\n".join(_sections(obj, path, "")).lstrip("\n") + "\n"


def _sections(obj, path: str, header: str) -> list[str]:
    """[header + plain keys] then the sub-tables; a header with no keys of its own is left out
    (TOML creates it implicitly)."""
    plain, tables = [], []
    if kind_of(obj) is not None:
        plain.append(f"kind = {_scalar(kind_of(obj))}")
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        sub = f"{path}.{f.name}" if path else f.name
        if dataclasses.is_dataclass(v):
            tables += _sections(v, sub, f"\n[{sub}]")
        elif isinstance(v, tuple) and v and dataclasses.is_dataclass(v[0]):
            for item in v:
                tables += _sections(item, sub, f"\n[[{sub}]]")
        elif v is not None:
            plain.append(f"{f.name} = {_scalar(v, f.metadata.get('hex', 0))}")
    head = [header] if header and (plain or header.startswith("\n[[")) else []
    return head + plain + tables


def plain(obj, table: type | None = None):
    """Table *obj* as the data :func:`build` reads back (sub-tables as dicts, tuples as lists,
    None left out); with *table* (a base of obj's class) only that table's keys."""
    if dataclasses.is_dataclass(obj):
        return {f.name: plain(v) for f in dataclasses.fields(table or obj)
                if (v := getattr(obj, f.name)) is not None}
    if isinstance(obj, tuple):
        return [plain(v) for v in obj]
    return obj


# -- documentation -------------------------------------------------------------------------
def rows(cls, prefix: str = "") -> list[tuple[str, str, str, str, str]]:
    """(key, unit, default, valid values, meaning) for every key of *cls* and its sub-tables;
    keys are dotted paths, ``[]`` marking an array of tables (``anchors[].x``)."""
    out = []
    kinds = getattr(cls, "KINDS", None)
    classes = [c for _, c in kinds.items()] if kinds else [cls]
    if kinds:
        out.append((prefix + "kind", "", "required", ", ".join(f"`{k}`" for k in kinds.names()),
                    "the kind of entry"))
    shared: dict[tuple, list] = {}  # a key as documented -> the kinds declaring it so
    for c in classes:
        hints = typing.get_type_hints(c)
        for f in dataclasses.fields(c):
            name = prefix + f.name
            tp = hints[f.name]
            origin, args = typing.get_origin(tp), typing.get_args(tp)
            if origin in (typing.Union, types.UnionType) and (_is_table(args[0]) or _is_tables(args[0])):
                tp = args[0]  # an optional table or array of tables: its keys
                origin, args = typing.get_origin(tp), typing.get_args(tp)
            if _is_table(tp) or (origin is tuple and args and _is_table(args[0])):
                if name not in shared:
                    shared[name] = []
                    out.extend(rows(tp if _is_table(tp) else args[0],
                                    name + ("." if _is_table(tp) else "[].")))
                continue
            default = "required" if f.default is MISSING else (
                "none" if f.default is None else _scalar(f.default, f.metadata.get("hex", 0)))
            valid = "; ".join(c.must.replace("must be ", "") for c in f.metadata.get("checks", ()))
            row = (name, f.metadata.get("unit", ""), default, valid, f.metadata.get("doc", ""))
            if len(classes) == 1:
                out.append(row)
            elif row in shared:  # kinds that declare a key alike share its row
                shared[row].append(c.KIND)
            else:
                shared[row] = [c.KIND]
                out.append(row)
    if len(classes) > 1:
        out = [r if r not in shared else r[:4] + (f"({', '.join(shared[r])}) {r[4]}",)
               for r in out]
    return out


def markdown_table(cls) -> str:
    lines = ["| key | unit | default | valid | meaning |", "|---|---|---|---|---|"]
    for name, unit, default, valid, doc in rows(cls):
        lines.append(f"| `{name}` | {unit} | `{default}` | {valid} | {doc} |")
    return "\n".join(lines) + "\n"
