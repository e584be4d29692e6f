"""Parameter sweeps: one scenario key over a list or a range of values, crossed with the seeds.

``Vary.parse("ranging.sigma0_m=0.1,0.3,0.6")`` or ``Vary.parse("ranging.sigma0_m=0.1..0.5:0.1")``
names a key of the scenario's TOML (:meth:`Scenario.to_toml`: tables by name, an array of
tables' entry by its 0-based index, e.g. ``anchors.0.range_bias_m``) and its values; each
value is read as TOML (a number, true/false, a quoted string; a bare word is a string), a
range ``A..B:STEP`` as the numbers A, A + STEP, ... up to B included. :func:`variant` is the
scenario with the key set, checked as a scenario file is (a key it does not have, or a value
it refuses, is one line naming it). The sweep (lab.sweep.run) runs every (value, seed) and
tags each cell with its value (the ``variant`` column); each value gets the tables of a
plain sweep, and :func:`overview` sets the values side by side.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass

from navtwin.common import tomlfile
from navtwin.emulator.scenario import Scenario, ScenarioError, parse_scenario

from .evaluate import ci_text

#: Values a parameter sweep takes at most (each is a sweep of its own over the seeds).
MAX_VALUES = 100


class VaryError(ValueError):
    """A parameter sweep that cannot run: one line naming the problem and the fix."""


@dataclass(frozen=True)
class Vary:
    """Scenario key *key* (dotted) over *values*."""

    key: str
    values: tuple

    @classmethod
    def parse(cls, text: str) -> Vary:
        """``KEY=V1,V2,...`` or ``KEY=A..B:STEP``."""
        key, eq, spec = (s.strip() for s in text.partition("="))
        if not eq or not key or not spec:
            raise VaryError(f"vary: {text!r} is not KEY=VALUES; write e.g. "
                            "ranging.sigma0_m=0.1,0.3 or ranging.sigma0_m=0.1..0.5:0.1")
        values = _range(spec) if ".." in spec else tuple(_value(v) for v in spec.split(","))
        if len(set(map(label, values))) != len(values):
            raise VaryError(f"vary: {spec!r} names a value twice; give each once")
        if not 1 <= len(values) <= MAX_VALUES:
            raise VaryError(f"vary: {len(values)} values; give 1 to {MAX_VALUES}")
        return cls(key, values)

    def as_meta(self) -> dict:
        return {"key": self.key, "values": [label(v) for v in self.values]}


def label(value) -> str:
    """A value as the cells' ``variant`` column and the tables name it."""
    if isinstance(value, bool):
        return str(value).lower()
    return repr(value) if isinstance(value, float) else str(value)  # repr: never two alike


def _value(text: str):
    text = text.strip()
    if not text:
        raise VaryError("vary: an empty value; separate the values by single commas")
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word: a string, as a scenario's enumerations take them


def _range(spec: str) -> tuple[float, ...]:
    span, colon, step = spec.partition(":")
    a, _, b = span.partition("..")
    try:
        a, b, step = float(a), float(b), float(step) if colon else math.nan
    except ValueError:
        a = math.nan
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(step) and step > 0
            and b >= a):
        raise VaryError(f"vary: {spec!r} is not a range A..B:STEP with A <= B and STEP > 0; "
                        "write e.g. 0.1..0.5:0.1")
    n = math.floor((b - a) / step + 1e-9) + 1
    if n > MAX_VALUES:
        raise VaryError(f"vary: {spec!r} makes {n} values; give at most {MAX_VALUES} (a "
                        "larger STEP)")
    # each value from A and its index, rounded to the step's digits: 0.1 + 2 x 0.1 is 0.3
    digits = max(0, -math.floor(math.log10(step)) + 6)
    return tuple(round(a + i * step, digits) for i in range(n))


def variant(sc: Scenario, key: str, value) -> Scenario:
    """*sc* with its TOML's *key* set to *value*, parsed and checked as a scenario file is."""
    data = tomlfile.parse(sc.to_toml(), sc.name)
    node, parts = data, key.split(".")
    for i, part in enumerate(parts[:-1]):
        node = _child(node, part, ".".join(parts[:i + 1]), key)
    last = parts[-1]
    if not isinstance(node, dict) or last not in node:
        raise VaryError(f"vary: {key}: scenario {sc.name} has no such key; name one of its "
                        "TOML's keys (docs/scenarios.md lists them)")
    if isinstance(node[last], (dict, list)) and not isinstance(value, type(node[last])):
        raise VaryError(f"vary: {key} is a table or array; name one of its keys")
    node[last] = value
    try:
        return parse_scenario(data, sc.name)
    except ScenarioError as e:
        raise VaryError(f"vary: {key} = {label(value)}: {e}") from None


def _child(node, part: str, path: str, key: str):
    if isinstance(node, list):
        if not part.isdigit() or int(part) >= len(node):
            raise VaryError(f"vary: {key}: {path} is not an entry of the array (0 to "
                            f"{len(node) - 1}); give its 0-based index")
        return node[int(part)]
    if not isinstance(node, dict) or part not in node:
        raise VaryError(f"vary: {key}: the scenario has no table {path}; name one of its "
                        "TOML's keys")
    return node[part]


def overview(key: str, summaries: dict, figure: str = "mean") -> tuple[list[str], list[list[str]]]:
    """The values side by side: a row per filter, a column per value, each cell the
    filter's *figure* (a lab.sweep FIGURES key) over seeds ± its 95 % half-width, from
    *summaries* (value label -> lab.sweep.summarise of that value's cells); *key* names
    the columns."""
    labels = list(summaries)
    filters = list(next(iter(summaries.values()))["filters"]) if summaries else []
    head = ["filter", *(f"{key} = {v}" for v in labels)]
    return head, [[f, *(ci_text(summaries[v]["filters"][f][figure]) for v in labels)]
                  for f in filters]
