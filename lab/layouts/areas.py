"""Paper 004's Tables 2 and 3 (errors in the training areas and in the WSN outages after them),
their layout in the sweep's tables and the report (lab.layouts); the figures are lab.areas's.

Each table of the PAPER_FIGURES entry (``"tables"``) has 004's rows (our track: its label), a
column per figure and window in 004's order (x, y, vx, vy error, each in window 1 then 2), and
the mean horizontal error per window after them (ours: 004 gives none). Under the tables, the
paired comparisons each table names (a - b of the mean horizontal error, per window): over a
sweep, with the 95 % half-width and the paired t test's p, Holm-adjusted over every comparison
shown (the family of both tables), decided for a track only when that adjusted p is below
:data:`ALPHA` (equivalently: its CI at the Holm step's level, 1 - ALPHA / (m - i + 1) for the
i-th smallest p, excludes 0, and every smaller p was decided). Holm rather than the plain
95 % CIs: ten comparisons at 5 % each would decide at least one by chance in two sweeps out
of five without any difference. In one run (the report): the differences alone.
"""
from __future__ import annotations

import math

from .. import areas, evaluate
from ..evaluate import ALPHA, WINDOW_FIGURES, ci_text, decide, mean_ci, p_text, paired
#: 004's symbol and unit of each per-axis figure.
HEADINGS = {"x_mean": "δ(δrx) m", "y_mean": "δ(δry) m", "vx_mean": "δ(δvx) m/s",
            "vy_mean": "δ(δvy) m/s"}


def columns(sc) -> tuple[str, ...]:
    return areas.columns(len(sc.anchor_grids))


def figures(sc, truth: dict, estimates: dict, offset_s: float = 0.0) -> dict:
    return areas.window_errors(areas.boxes(sc), truth, estimates, offset_s)


def _label(window: str) -> str:
    """``outage2`` -> ``outage 2``."""
    return window.rstrip("0123456789") + " " + window[len(window.rstrip("0123456789")):]


def _layout(spec: dict, n_areas: int) -> tuple[list[str], list[str], list[str]]:
    """(windows, columns, headings) of one table over *n_areas* areas: 004's per-axis figures
    in its order, then our mean horizontal error per window."""
    windows = [f"{spec['window']}{k}" for k in range(1, n_areas + 1)]
    cols = [f"{w}_{f}" for f in WINDOW_FIGURES for w in windows] + [f"{w}_mean" for w in windows]
    heads = [f"{HEADINGS[f]} {_label(w)}" for f in WINDOW_FIGURES for w in windows]
    heads += [f"mean m {_label(w)} (ours)" for w in windows]
    return windows, cols, heads


def _n_areas(rows) -> int:
    """The training areas the rows have windows of (their ``area<k>_mean`` columns)."""
    return max((k for r in rows for k in range(1, 100) if f"area{k}_mean" in r), default=0)


def _finite(values) -> list[float]:
    return [v for v in values if v is not None and math.isfinite(v)]


def summary(ok: dict, per: dict, scenario: str) -> dict | None:
    """004's tables of a sweep: per table its rows (label, track, seeds, each column's mean
    over seeds and 95 % half-width, 004's figure or None) and its paired comparisons, Holm-
    adjusted over all of them (module doc); ``windows``: each window's duration over seeds."""
    paper = evaluate.PAPER_FIGURES[scenario]
    n = _n_areas(r for cells in ok.values() for r in cells.values())
    if not n:
        return None
    tables = []
    for title, spec in paper["tables"].items():
        windows, cols, _ = _layout(spec, n)
        rows = [{"label": label, "track": track, "seeds": per[track]["seeds"],
                 "figures": {c: mean_ci(_finite(r.get(c) for r in ok[track].values())) for c in cols},
                 "paper": {c: paper["figures"].get(track, {}).get(c) for c in cols}}
                for track, label in spec["rows"].items() if ok.get(track)]
        pairs = [{**paired(ok, a, b, f"{w}_mean"), "window": w}
                 for a, b in spec["pairs"] if ok.get(a) and ok.get(b) for w in windows]
        tables.append({"title": title, "what": spec["what"], "window": spec["window"],
                       "rows": rows, "pairs": pairs})
    family = [p for t in tables for p in t["pairs"]]
    decide(family)
    first = next(cells for cells in ok.values() if cells)
    durations = {w: mean_ci(_finite(r.get(f"{w}_duration_s") for r in first.values()))
                 for w in areas.window_names(n)}
    return {"paper": paper["paper"], "areas": n, "tables": tables, "durations": durations,
            "comparisons": len(family)}


def _cell(ours: tuple[float, float], theirs: float | None) -> str:
    return ci_text(ours) + ("" if theirs is None else f" ({theirs:.4f})")


def grids(section: dict):
    """004's tables of a sweep's section (:func:`summary`), each then its comparisons, then the
    windows' durations, as lab.layouts's grids."""
    paper, out = section["paper"], []
    for t in section["tables"]:
        _, cols, heads = _layout(t, section["areas"])
        rows = [[r["label"], r["track"], str(r["seeds"]),
                 *(_cell(r["figures"][c], r["paper"][c]) for c in cols)] for r in t["rows"]]
        out.append((f"Paper {paper} {t['title']}'s layout, the {t['what']} (lab.areas's windows): "
                    "each figure the mean over seeds of that seed's mean absolute error in the "
                    f"window, ± its 95 % half-width; ({paper}'s published figure); mean m: the "
                    f"mean horizontal error (ours, {paper} gives none)",
                    [f"{paper} {t['title']}", "track", "seeds", *heads], rows, 2))
        if t["pairs"]:
            out.append((f"Paired differences a - b of the mean horizontal error in each window "
                        "over the seeds both have (m, ± the 95 % half-width); p: the paired t "
                        f"test's, Holm-adjusted over the {section['comparisons']} comparisons "
                        f"shown; decided where below {ALPHA:g}",
                        ["a - b", "window", "decides", "seeds", "difference m", "Holm p"],
                        [[f"{p['a']} - {p['b']}", _label(p["window"]),
                          f"{p['better']} better" if p["better"] else "not decided",
                          str(p["seeds"]), ci_text((p["diff"], p["half"])), p_text(p["holm_p"])]
                         for p in t["pairs"]], 3))
    out.append(("The windows' durations on the truth's clock (s), mean over seeds ± its 95 % "
                "half-width", ["window", "duration s"],
                [[_label(w), ci_text(v, 1)] for w, v in section["durations"].items()], 1))
    return tuple(out)


def _number(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else v


def report_tables(run: dict) -> list[dict]:
    """004's tables of one run (lab.report): per table our figures of each row's track then
    004's (a row without a track), then the table's comparisons a - b of the mean horizontal
    error per window (one run: no interval); the windows' durations in the notes."""
    sc, paper = run["scenario"], run["paper"]
    n = len(sc.anchor_grids)
    errors = areas.window_errors(areas.boxes(sc), run["truth"], run["estimates"], run["offset_s"])
    out = []
    for title, spec in paper["tables"].items():
        windows, cols, heads = _layout(spec, n)
        rows = []
        for track, label in spec["rows"].items():
            if track not in errors:
                continue
            rows.append((label, track, *(_number(errors[track][c]) for c in cols)))
            if track in paper["figures"]:
                rows.append((f"{label}, paper {paper['paper']}", "",
                             *(paper["figures"][track].get(c) for c in cols)))
        if not rows:
            continue
        spans = ", ".join(f"{_label(w)} {next(iter(errors.values()))[f'{w}_duration_s']:.1f} s"
                          for w in windows)
        what = spec["what"][0].upper() + spec["what"][1:]
        out.append({"title": f"{what} (paper {paper['paper']} {title}'s layout)",
                    "head": [f"{paper['paper']} {title}", "track", *heads], "rows": rows,
                    "stats": cols,
                    "note": (f"Mean absolute error in each window (lab.areas: {spans}); mean m: "
                             f"the mean horizontal error (ours, {paper['paper']} gives none).")})
        diffs = [(f"{a} - {b}", _label(w),
                  _number(errors[a][f"{w}_mean"] - errors[b][f"{w}_mean"]))
                 for a, b in spec["pairs"] if a in errors and b in errors for w in windows]
        if diffs:
            out.append({"title": f"{what}: paired differences",
                        "head": ["a - b", "window", "mean error difference m"], "rows": diffs,
                        "stats": None,
                        "note": "One run: no interval; the sweep's tables give them over seeds "
                                "(docs/sweeps.md)."})
    return out
