"""Errors by window of a run through training areas and the outages between them (paper 004).

004 scores its filters separately inside its two training areas, where the WSN is present
(Table 2), and in the WSN outages after them (Table 3). Its areas are the scenario's anchor
grids (``sc.anchor_grids``, common.anchorgrid.AnchorGrid), in the order declared, each the
rectangle ``box`` = (x0, y0, x1, y1) its nodes span. Each estimate of a track falls in one
window, by the truth at its scenario time:

- ``area k``: the truth is inside box k (edges included);
- ``outage k``: not in an area, after the last ``area k`` estimate and before the first
  ``area k+1`` one (after the last area's: to the end of the run).

Estimates before the first area's, or in no window, are not scored here. Per window and track
(:data:`STATS`): the mean absolute error along x and y (004's δ(δrx), δ(δry), m) and of the
velocity along x and y (δ(δvx), δ(δvy), m/s), the mean horizontal position error (m), the
estimates scored and the window's duration on the truth's clock (s). 004 calls its figures
"mean errors" and defines them no further; the reading here is the mean of the absolute error:
its INS-only rows, errors growing from 0 with the time since the last fix, are all positive and
grow from area 1 to the longer outage 2 (7.8 to 72 m), which a mean of a signed error that
drifts either way would not do.

The truth's velocity is emulator.truth's ``vx``, ``vy`` (truth.csv carries them, every
millisecond), interpolated at the estimate's time like its position; nothing is differentiated.
A window's duration: for an area, from the first to the last truth sample inside its box; for
an outage, from the end of its area to the start of the next (or to the end of the truth).
"""
from __future__ import annotations

import math

import numpy as np

#: Per-window figures, with their units: mean |x|, |y|, |vx|, |vy| error, mean horizontal error,
#: estimates scored, the window's duration.
STATS = {"x_mean": "m", "y_mean": "m", "vx_mean": "m/s", "vy_mean": "m/s", "mean": "m",
         "n": "", "duration_s": "s"}


def boxes(sc) -> tuple[tuple[float, float, float, float], ...]:
    """The training areas of scenario *sc*: its anchor grids' rectangles, in order."""
    return tuple(g.box for g in sc.anchor_grids)


def window_names(n_areas: int) -> tuple[str, ...]:
    """``area1, outage1, area2, outage2, ...`` for *n_areas* training areas."""
    return tuple(f"{kind}{k}" for k in range(1, n_areas + 1) for kind in ("area", "outage"))


def columns(n_areas: int) -> tuple[str, ...]:
    """The per-run columns of *n_areas* areas: ``<window>_<stat>`` (e.g. ``outage2_vy_mean``)."""
    return tuple(f"{w}_{s}" for w in window_names(n_areas) for s in STATS)


def _inside(box, x, y) -> np.ndarray:
    x0, y0, x1, y1 = box
    return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def classify(boxes, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The window of each point (x, y) of a time-ordered series (the truth at each estimate's
    time): 2(k-1) for ``area k``, 2(k-1) + 1 for ``outage k`` (the index into
    :func:`window_names`), -1 for none (module doc)."""
    out = np.full(len(x), -1)
    inside = [_inside(b, x, y) for b in boxes]
    for k, mask in enumerate(inside):
        out[mask & (out < 0)] = 2 * k
    for k, mask in enumerate(inside):
        if not mask.any():
            continue
        start = np.flatnonzero(mask)[-1] + 1
        nxt = inside[k + 1] if k + 1 < len(inside) else None
        stop = np.flatnonzero(nxt)[0] if nxt is not None and nxt.any() else len(x)
        gap = slice(start, max(start, stop))
        out[gap] = np.where(out[gap] < 0, 2 * k + 1, out[gap])
    return out


def durations(boxes, truth: dict) -> np.ndarray:
    """Each window's duration (s) on the truth's clock, in :func:`window_names` order; 0 for a
    window the truth never reaches."""
    t = truth["t"]
    w = classify(boxes, truth["x"], truth["y"])
    out = np.zeros(2 * len(boxes))
    for k in range(len(boxes)):
        inside = np.flatnonzero(w == 2 * k)
        if not inside.size:
            continue
        out[2 * k] = t[inside[-1]] - t[inside[0]]
        nxt = np.flatnonzero(w == 2 * k + 2)
        end = t[nxt[0]] if nxt.size else t[-1]
        out[2 * k + 1] = end - t[inside[-1]]
    return out


def window_errors(boxes, truth: dict, estimates: dict, offset_s: float = 0.0
                  ) -> dict[str, dict[str, float]]:
    """Per track (estimates as lab.evaluate.load_estimates gives them, with ``vx``, ``vy``),
    over its estimates inside the truth's time span: the figures of :data:`STATS` of each window
    (module doc) as flat columns ``<window>_<stat>`` (:func:`columns`); a window without
    estimates has NaN figures and ``n`` 0."""
    names = window_names(len(boxes))
    span = durations(boxes, truth)
    out = {}
    for track, e in sorted(estimates.items()):
        t = e["t"] + offset_s
        keep = (t >= truth["t"][0]) & (t <= truth["t"][-1])
        t = t[keep]
        tx, ty = (np.interp(t, truth["t"], truth[a]) for a in ("x", "y"))
        err = np.abs(np.column_stack([e[a][keep] - np.interp(t, truth["t"], truth[a])
                                      for a in ("x", "y", "vx", "vy")]))
        horizontal = np.hypot(err[:, 0], err[:, 1])
        w = classify(boxes, tx, ty)
        row = {}
        for i, name in enumerate(names):
            m = w == i
            n = int(m.sum())
            means = err[m].mean(axis=0) if n else np.full(4, math.nan)
            row |= {f"{name}_x_mean": float(means[0]), f"{name}_y_mean": float(means[1]),
                    f"{name}_vx_mean": float(means[2]), f"{name}_vy_mean": float(means[3]),
                    f"{name}_mean": float(horizontal[m].mean()) if n else math.nan,
                    f"{name}_n": n, f"{name}_duration_s": float(span[i])}
        out[track] = row
    return out
