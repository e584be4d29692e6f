"""Papers' own table layouts in the sweep's tables and the report, one module per layout.

A PAPER_FIGURES entry (lab.evaluate) names its layout (``"layout": "latlon"``); the module of
that name here gives, for its scenario:

- ``columns(sc)``: per-run columns it adds to each of the sweep's cells, ``figures(sc, truth,
  estimates, offset_s)`` their values per track (lab.areas's windows; none for latlon, whose
  figures are position_errors's own);
- ``summary(ok, per, scenario)``: its section of a sweep's summary (ok: track -> seed -> row;
  per: the per-track figures over seeds), None when none of its rows is there;
- ``grids(section)``: that section as (title, heading, rows, number of name columns set to the
  left), printed by the sweep as text and as Markdown;
- ``report_tables(run)``: its tables of one run (``navtwin report``), as (title, heading, rows,
  note).

The summary holds the section under the layout's name (``summary["latlon"]``).
"""
from __future__ import annotations

from types import ModuleType

from .. import evaluate
from . import areas, latlon

LAYOUTS: dict[str, ModuleType] = {"latlon": latlon, "areas": areas}


def of(scenario: str | None) -> tuple[str, ModuleType] | None:
    """(name, module) of the layout *scenario*'s paper gives, or None."""
    name = evaluate.PAPER_FIGURES.get(scenario, {}).get("layout")
    return None if name is None else (name, LAYOUTS[name])


def grids(summary: dict):
    """The (title, heading, rows, left) grids of every layout section in *summary*."""
    return tuple(g for name, module in LAYOUTS.items() if name in summary
                 for g in module.grids(summary[name]))
