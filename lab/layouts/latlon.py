"""Paper 003's Table 1 (latitude and longitude errors of the SINS alone, the centroid and the
weighted centroid), its layout in the sweep's tables (lab.layouts); the figures are
lab.evaluate's (:data:`~navtwin.lab.evaluate.LATLON`, in every cell already)."""
from __future__ import annotations

from .. import evaluate
from ..evaluate import ALPHA, ci_text, decide, paired


def columns(sc) -> tuple[str, ...]:
    return ()


def figures(sc, truth: dict, estimates: dict, offset_s: float = 0.0) -> dict:
    return {}


def summary(ok: dict, per: dict, scenario: str) -> dict | None:
    """003 Table 1's layout of a summary: ``rows``, per paper row (evaluate.latlon_rows) its
    label, our track, its seeds and each figure of evaluate.LATLON over seeds with the paper's
    beside it; ``pairs``, each row's track against every row above it (the weighted centroid
    against the centroid, each against the SINS alone), the paired difference of each figure,
    decided with Holm over every pair and figure (evaluate.decide)."""
    table = evaluate.latlon_rows(scenario, tuple(per))
    if not table:
        return None
    paper = evaluate.PAPER_FIGURES[scenario]["figures"]
    rows = [{"label": label, "track": track, "seeds": per[track]["seeds"],
             **{m: per[track][m] for m in evaluate.LATLON},
             "paper": {m: paper[key][m] for m in evaluate.LATLON}} for label, track, key in table]
    pairs = [{"a": a["track"], "b": b["track"],
              **{m: paired(ok, a["track"], b["track"], m) for m in evaluate.LATLON}}
             for i, a in reversed(list(enumerate(rows))) for b in reversed(rows[:i])]
    decide([p[m] for p in pairs for m in evaluate.LATLON])
    return {"paper": evaluate.PAPER_FIGURES[scenario]["paper"], "rows": rows, "pairs": pairs}


def grids(ll: dict) -> tuple[tuple[str, list[str], list[list[str]], int], ...]:
    """003 Table 1's layout of a summary's ``latlon`` as (title, heading, rows, number of
    columns of names, set to the left): the figures, ours over seeds with the paper's in
    parentheses, then, where two methods or more are there, their paired differences."""
    paper, figs = ll["paper"], list(evaluate.LATLON)
    head = [f"{paper} Table 1", "track", "seeds", *evaluate.LATLON.values()]
    rows = [[r["label"], r["track"], str(r["seeds"]),
             *(f"{ci_text(r[m])} ({r['paper'][m]:.4f})" for m in figs)] for r in ll["rows"]]
    pair_head = ["a - b", "seeds", *evaluate.LATLON.values()]
    pair_rows = [[f"{p['a']} - {p['b']}", str(p[figs[0]]["seeds"]),
                  *(f"{ci_text((p[m]['diff'], p[m]['half']), 3)} "
                    f"{'(' + p[m]['better'] + ')' if p[m]['better'] else '(~)'}" for m in figs)]
                 for p in ll["pairs"]]
    grids = [(f"Paper {paper} Table 1's layout (m; average: mean absolute error, max: maximum "
              "absolute error, std: standard deviation of the signed error, along north for "
              "latitude and east for longitude): each figure the mean over seeds of that seed's "
              f"figure, ± its 95 % half-width; ({paper}'s published figure)", head, rows, 2)]
    if pair_rows:  # one row of the paper's present: nothing to pair
        grids.append(("Paired differences a - b over the seeds both have (m, ± the 95 % "
                      "half-width); (name): the track it decides for, its paired t test's p "
                      f"Holm-adjusted over the {len(ll['pairs']) * len(figs)} comparisons "
                      f"below {ALPHA:g}; (~): not decided",
                      pair_head, pair_rows, 1))
    return tuple(grids)



#: The report's note under the table: what each figure is (lab.evaluate says why).
NOTE = ("Latitude error: along north; longitude error: along east (m), through the "
        "scenario's site and x azimuth. Average: the mean absolute error; max: the "
        "maximum absolute error; std: the standard deviation of the signed error "
        "(003 defines none of them; docs/lab.md, \"Latitude and longitude\").")


def report_tables(run: dict) -> list[dict]:
    """003 Table 1's layout of one run (lab.report): per paper row (evaluate.latlon_rows) its
    label, our track and our LATLON figures, then a row of the paper's own (no track)."""
    paper, rows = run["paper"], []
    for label, track, key in evaluate.latlon_rows(run["scenario"].name, run["errors"]):
        rows.append((label, track, *(run["errors"][track][m] for m in evaluate.LATLON)))
        rows.append((f"{label}, paper {paper['paper']}", "",
                     *(paper["figures"][key][m] for m in evaluate.LATLON)))
    if not rows:
        return []
    return [{"title": f"Latitude and longitude (paper {paper['paper']} Table 1's layout)",
             "head": ["method", "track", *evaluate.LATLON.values()], "rows": rows,
             "stats": list(evaluate.LATLON), "note": NOTE}]
