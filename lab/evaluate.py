"""Accuracy of a host's estimates against the emulator's truth, beside paper 000's figures.

Truth is the emulator's ``truth.csv`` (a header row with at least ``t,x,y``; ``t`` in integer
nanoseconds of scenario time, one row per millisecond); estimates are the host's JSON lines,
read from its output file like any other program's. Each estimate is compared with the truth
interpolated at its time, shifted by ``offset_s`` (scenario time = host time + offset_s).

Latitude and longitude errors (paper 003's Table 1): given the scenario's local frame
(common.geodesy.LocalFrame: its [site] and [area] x_azimuth_deg), an estimate's and the truth's
x, y (on the floor, z = 0) become latitude and longitude, and their differences metres along
north and east: d phi R_M(phi) and d lam R_N(phi) cos phi at the truth's latitude phi
(:func:`north_east_errors`), right for any azimuth of the area's x. Per run, for each of the
two: ``lat_mean`` / ``lon_mean`` the mean of |error|, ``lat_max`` / ``lon_max`` the max of
|error|, ``lat_std`` / ``lon_std`` the standard deviation (population, ddof 0) of the signed
error. 003 defines none of its "average deviation", "maximum deviation" and "standard
deviation"; this reading is the one its figures fit: its Single SINS row, an error growing
from 0, has an average (13.60 m) about half its maximum (26.93 m), which a mean of a signed
error that changes sign would not give, and a standard deviation (6.58 m) below its average,
as the spread of a ramp about its own mean is (27 / sqrt(12) = 7.8 m for 0..27).
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
from scipy.stats import chi2
from scipy.stats import t as student_t

from navtwin.common.geodesy import LocalFrame, meridian_radius, transverse_radius

#: Paper 000, section 3.3 and 4.3: mean position error (m) on the office run.
PAPER_MEAN_ERROR_M = {"sins": 0.69, "wsn": 0.64, "kf": 0.71, "ekf": 0.63, "ukf": 0.59}
PAPER_MAX_ERROR_M = {"sins": 1.27, "wsn": 0.94}
#: 004's per-window columns in its tables' order: x, y, vx, vy error, each in window 1 then 2.
WINDOW_FIGURES = ("x_mean", "y_mean", "vx_mean", "vy_mean")


def _windows(kind: str, *figures: float) -> dict[str, float]:
    """One row of 004's Table 2 or 3 (its figures as printed, in its column order) as
    lab.areas columns of window *kind* ("area" or "outage") 1 and 2."""
    keys = [f"{kind}{k}_{f}" for f in WINDOW_FIGURES for k in (1, 2)]
    return dict(zip(keys, figures, strict=True))


#: The published figures the report and the sweep put beside ours, by scenario: per track,
#: keys of :func:`position_errors`. Paper 001's LC, TC and FATCI are our lc, tc and fatci.
#: From shared/specs/scenarios.md.
PAPER_FIGURES = {
    "office": {"paper": "000", "note": "section 3.3 and 4.3, mean error of each filter and max "
               "of the pure SINS and WSN on the office run (its variances are of the error "
               "magnitude, not per axis, and are not shown)",
               # the paper gives no time: one loop of the taped line, 70 s in the scenario
               "experiment": "one loop of the taped line", "duration_s": 70.0,
               "figures": {n: {"mean": m, **({"max": PAPER_MAX_ERROR_M[n]}
                                              if n in PAPER_MAX_ERROR_M else {})}
                           for n, m in PAPER_MEAN_ERROR_M.items()}},
    "corridor": {"paper": "001", "note": "Table 1, the corridor's two loops",
                 "experiment": "two loops of the corridor", "duration_s": 127.0,
                 "figures": {"lc": {"max": 0.3748, "mean": 0.0956, "x_var": 0.0077, "y_var": 0.0052},
                             "tc": {"max": 0.2344, "mean": 0.0682, "x_var": 0.0049, "y_var": 0.0011},
                             "fatci": {"max": 0.1488, "mean": 0.0384, "x_var": 0.0017,
                                       "y_var": 0.0002}}},
    # 003 Table 1's rows are methods: Single SINS, the traditional (centroid) and its own
    # (weighted centroid) method; "tracks" maps each to ours, the first present in a run
    # ("geosins", the free geodetic SINS, else the flat "sins")
    "rssi-centroid": {"paper": "003", "note": "Table 1, latitude and longitude error of the "
                      "SINS alone and aided by the centroid and by the weighted centroid",
                      "experiment": "1500 s north at 1 m/s from 32 N 118 E", "duration_s": 1500.0,
                      "layout": "latlon",
                      "tracks": {"geosins": ("Single SINS", ("geosins", "sins")),
                                 "centroid": ("centroid (traditional method)", ("centroid",)),
                                 "wcl": ("weighted centroid (003's method)", ("wcl",))},
                      "figures": {"geosins": {"lat_mean": 13.5977, "lon_mean": 9.1389,
                                              "lat_max": 26.9316, "lon_max": 18.2245,
                                              "lat_std": 6.5798, "lon_std": 7.2239},
                                  "centroid": {"lat_mean": 1.6007, "lon_mean": 2.6412,
                                               "lat_max": 10.8778, "lon_max": 16.9741,
                                               "lat_std": 2.1908, "lon_std": 3.4389},
                                  "wcl": {"lat_mean": 0.9511, "lon_mean": 1.3758,
                                          "lat_max": 6.3075, "lon_max": 9.3784,
                                          "lat_std": 1.3024, "lon_std": 1.8247}}},
    # 004 Tables 2 and 3: mean absolute errors per axis in each training area (Table 2) and in
    # the WSN outage after it (Table 3), lab.areas's windows; "tables" names each table's rows
    # (our track: 004's row label) and the paired comparisons shown under it (a - b on the
    # mean horizontal error of each window). Table 3 adds "hinf" without figures: the HF's
    # INS coasting from its last fix, the baseline of what bridging adds. As printed: Table 2's
    # INS-only area 2 has 2.0649 m/s for both vx and vy, and Table 3's caption names "KF, and
    # HF" for its BP and LS-SVM rows.
    "outage-bridging": {"paper": "004", "note": "Tables 2 and 3, mean absolute position and "
                        "velocity error along x and y in the two training areas and in the WSN "
                        "outage after each",
                        # 004 gives no time: its path's 656 m at the 2 m/s of the scenario
                        "experiment": "the path from (650, 0) to (130, 400) through two "
                        "training areas", "duration_s": 328.0,
                        "layout": "areas",
                        "tables": {"Table 2": {"window": "area", "what": "training areas",
                                               "rows": {"sins": "INS-only", "kf-rel": "KF",
                                                        "hinf": "HF"},
                                               "pairs": (("hinf", "kf-rel"), ("hinf", "sins"))},
                                   "Table 3": {"window": "outage", "what": "WSN outages",
                                               "rows": {"sins": "INS-only", "hinf+bp": "BP",
                                                        "hinf+lssvm": "LS-SVM",
                                                        "hinf": "HF coasting (ours)"},
                                               "pairs": (("hinf+lssvm", "hinf+bp"),
                                                         ("hinf+lssvm", "sins"),
                                                         ("hinf+lssvm", "hinf"))}},
                        "figures": {
                            "sins": _windows("area", 7.8315, 40.6179, 4.7923, 36.0891, 0.6584,
                                             2.0649, 1.5777, 2.0649) |
                            _windows("outage", 12.1524, 72.4795, 8.7879, 70.0089, 0.8897,
                                     3.0793, 2.0265, 6.0012),
                            "kf-rel": _windows("area", 2.9170, 14.9663, 1.7916, 13.2591, 0.2715,
                                               0.3155, 0.5984, 0.8856),
                            "hinf": _windows("area", 0.3881, 0.4958, 0.5338, 0.8464, 0.1064,
                                             0.1041, 0.1008, 0.0932),
                            "hinf+bp": _windows("outage", 5.2628, 36.4784, 4.9441, 36.5174,
                                                0.6502, 1.1008, 0.8096, 1.6045),
                            "hinf+lssvm": _windows("outage", 0.5916, 5.2938, 0.4676, 4.6548,
                                                   0.0786, 0.0092, 0.0754, 0.0567)}},
    "corridor-outage": {"paper": "001", "note": "section 5.3, max error with anchor 2 silent "
                        "from 18 to 23 s and from 40 to 45 s",
                        "experiment": "the corridor with anchor 2's two outages", "duration_s": 60.0,
                        "figures": {"lc": {"max": 1.49}, "tc": {"max": 0.25},
                                    "fatci": {"max": 0.15}}},
}


def load_truth(path: str | Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = np.array([[float(v) for v in row] for row in reader], dtype=float)
    truth = {name: rows[:, i] for i, name in enumerate(header)}
    truth["t"] = truth["t"] / 1e9  # seconds, like the estimates
    return truth


def load_estimates(lines, vehicle: int = 1) -> dict[str, dict[str, np.ndarray]]:
    """Vehicle *vehicle*'s estimate JSON lines (an iterable of str, or a path) grouped by
    filter (lines written before estimates named their vehicle are vehicle 1's): per filter
    arrays ``t, x, y``, ``vx, vy``, ``cov`` (N x 2 x 2, the position block of the line's
    covariance) and ``extrapolated``."""
    if isinstance(lines, (str, Path)):
        lines = Path(lines).read_text().splitlines()
    by_filter: dict[str, list] = {}
    for line in lines:
        if not line.strip():
            continue
        e = json.loads(line)
        if "filter" in e and e.get("vehicle", 1) == vehicle:
            c = e["cov"]
            by_filter.setdefault(e["filter"], []).append(
                (e["t"], e["x"], e["y"], c[0], c[1], c[4], c[5], e.get("extrapolated", False),
                 e["vx"], e["vy"]))
    out = {}
    for k, v in by_filter.items():
        a = np.array(v, dtype=float)
        out[k] = {"t": a[:, 0], "x": a[:, 1], "y": a[:, 2], "cov": a[:, 3:7].reshape(-1, 2, 2),
                  "extrapolated": a[:, 7].astype(bool), "vx": a[:, 8], "vy": a[:, 9]}
    return out


def axis_errors(truth: dict, e: dict, offset_s: float = 0.0) -> np.ndarray:
    """Signed error (m) of each estimate of one filter, N x 2 (x, y), against the truth
    interpolated at its scenario time ``t + offset_s``."""
    t = e["t"] + offset_s
    return np.column_stack((e["x"] - np.interp(t, truth["t"], truth["x"]),
                            e["y"] - np.interp(t, truth["t"], truth["y"])))


def north_east_errors(frame: LocalFrame, truth: dict, e: dict, offset_s: float = 0.0) -> np.ndarray:
    """Signed error (m) of each estimate of one filter along north and east, N x 2: the
    latitude and longitude error as 003 gives them, through *frame* (the scenario's)."""
    t = e["t"] + offset_s
    est = np.column_stack((e["x"], e["y"], np.zeros(len(t))))
    true = np.column_stack((np.interp(t, truth["t"], truth["x"]), np.interp(t, truth["t"], truth["y"]),
                            np.zeros(len(t))))
    lat_e, lon_e, _ = frame.geodetic(est)
    lat_t, lon_t, _ = frame.geodetic(true)
    phi = np.radians(lat_t)
    d_lon = (lon_e - lon_t + 180.0) % 360.0 - 180.0  # across the antimeridian too
    return np.column_stack((np.radians(lat_e - lat_t) * meridian_radius(phi),
                            np.radians(d_lon) * transverse_radius(phi) * np.cos(phi)))


#: Per-run latitude/longitude figures (:func:`latlon_figures`), in 003 Table 1's column order,
#: with the headings the tables give them.
LATLON = {"lat_mean": "latitude average m", "lon_mean": "longitude average m",
          "lat_max": "latitude max m", "lon_max": "longitude max m",
          "lat_std": "latitude std m", "lon_std": "longitude std m"}


def latlon_figures(ne: np.ndarray) -> dict[str, float]:
    """003's Table 1 figures of north/east errors *ne* (N x 2): mean and max of |error|,
    standard deviation (ddof 0) of the signed error, for latitude (north) and longitude (east)."""
    out = {}
    for axis, v in (("lat", ne[:, 0]), ("lon", ne[:, 1])):
        out |= {f"{axis}_mean": float(np.abs(v).mean()), f"{axis}_max": float(np.abs(v).max()),
                f"{axis}_std": float(v.std())}
    return {k: out[k] for k in LATLON}


def error(truth: dict, e: dict, offset_s: float = 0.0) -> np.ndarray:
    """Horizontal position error (m) of each estimate of one filter (arrays ``t, x, y``)
    against the truth interpolated at its scenario time ``t + offset_s``."""
    return np.hypot(*axis_errors(truth, e, offset_s).T)


#: Two-sided 95 % band of a consistent 2-D position NEES (chi-square, 2 degrees of freedom).
NEES_BAND_95 = (float(chi2.ppf(0.025, 2)), float(chi2.ppf(0.975, 2)))


def nees(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared e^T P^-1 e of each (x, y) error against the
    estimate's own position covariance; NaN where that covariance is not positive definite
    (the pure SINS track reports none)."""
    a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = a * d - b * b
    ok = (a > 0) & (det > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = (d * err[:, 0] ** 2 - 2 * b * err[:, 0] * err[:, 1] + a * err[:, 1] ** 2) / det
    return np.where(ok, q, np.nan)


def position_errors(truth: dict, estimates: dict, offset_s: float = 0.0,
                    skip_s: float = 0.0, frame: LocalFrame | None = None) -> dict[str, dict[str, float]]:
    """Per filter, over estimates inside the truth's time span and after *skip_s* of scenario
    time: mean, max and RMS horizontal position error (m), the number of estimates, paper
    001's Table 1 figures (``x_min``/``x_max``, ``x_var``, ``y_min``/``y_max``, ``y_var`` of
    the signed per-axis errors), where the filter reports a covariance, its mean NEES
    and the share of NEES inside the 95 % band (``nees_mean``, ``nees_in_band``; None
    without one) and, given the scenario's *frame*, 003's latitude/longitude figures
    (:data:`LATLON`, :func:`latlon_figures`)."""
    out = {}
    t_truth = truth["t"]
    for name, e in sorted(estimates.items()):
        t = e["t"] + offset_s
        keep = (t >= max(t_truth[0], skip_s)) & (t <= t_truth[-1])
        if not keep.any():
            continue
        xy = axis_errors(truth, e, offset_s)[keep]
        err = np.hypot(*xy.T)
        q = nees(xy, e["cov"][keep]) if "cov" in e else np.full(len(err), np.nan)
        q = q[np.isfinite(q)]
        lo, hi = NEES_BAND_95
        out[name] = {"mean": float(err.mean()), "max": float(err.max()),
                     "rms": float(math.sqrt((err ** 2).mean())), "n": int(keep.sum()),
                     "x_min": float(xy[:, 0].min()), "x_max": float(xy[:, 0].max()),
                     "x_var": float(xy[:, 0].var()),
                     "y_min": float(xy[:, 1].min()), "y_max": float(xy[:, 1].max()),
                     "y_var": float(xy[:, 1].var()),
                     "nees_mean": float(q.mean()) if q.size else None,
                     "nees_in_band": float(((q >= lo) & (q <= hi)).mean()) if q.size else None}
        if frame is not None:
            out[name] |= latlon_figures(north_east_errors(frame, truth, e, offset_s)[keep])
    return out


def latlon_rows(scenario: str | None, present) -> list[tuple[str, str, str]]:
    """(the paper's row, our track, the paper's figures' key) of each row of *scenario*'s
    latitude/longitude Table 1 (a PAPER_FIGURES entry with ``"layout": "latlon"``), our track
    the first of the row's candidates in *present*; rows with none are left out, and a
    scenario without that layout has none."""
    paper = PAPER_FIGURES.get(scenario, {})
    if paper.get("layout") != "latlon":
        return []
    out = []
    for key, (label, candidates) in paper["tracks"].items():
        track = next((c for c in candidates if c in present), None)
        if track is not None:
            out.append((label, track, key))
    return out


def has_paper_means(scenario: str | None) -> bool:
    """Whether *scenario*'s paper gives a mean or max position error of some track (000's and
    001's do; 003 gives its errors in latitude and longitude only)."""
    figures = PAPER_FIGURES.get(scenario, {}).get("figures", {})
    return any({"mean", "max"} & set(v) for v in figures.values())


def paper_cell(scenario: str | None, name: str) -> str:
    """The published mean (max) of track *name* on *scenario*, as text ('' if none)."""
    fig = PAPER_FIGURES.get(scenario, {}).get("figures", {}).get(name, {})
    return " ".join(f"{fig[k]:.2f}" if k == "mean" else f"({fig[k]:.2f})"
                    for k in ("mean", "max") if k in fig)


def table(errors: dict[str, dict[str, float]], scenario: str | None = "office") -> str:
    """A text table of the errors beside the paper's figures for *scenario* (PAPER_FIGURES)."""
    pub = PAPER_FIGURES.get(scenario)
    head = f"paper {pub['paper']} mean (max)" if has_paper_means(scenario) else ""
    w = max([len("filter"), *map(len, errors)]) + 1  # the track names' column (centroid: 8)
    lines = [f"{'filter':<{w}}{'mean m':>9}{'max m':>9}{'rms m':>9}{'n':>7}   {head}".rstrip()]
    for name, e in errors.items():
        lines.append(f"{name:<{w}}{e['mean']:9.3f}{e['max']:9.3f}{e['rms']:9.3f}{e['n']:7d}   "
                     f"{paper_cell(scenario, name)}".rstrip())
    rows = [(label, track, key) for label, track, key in latlon_rows(scenario, errors)
            if set(LATLON) <= set(errors[track])]
    if rows:  # 003's Table 1: latitude/longitude figures, ours then the paper's (in parentheses)
        lw = max(len(label) for label, _, _ in rows) + 1
        lines += ["", f"{'paper ' + pub['paper'] + ' Table 1':<{lw}}{'track':<{w}}" +
                  "".join(f"{h.removesuffix(' m'):>20}" for h in LATLON.values()) + "   (m)"]
        for label, track, key in rows:
            ours, theirs = errors[track], pub["figures"][key]
            cells = (f"{ours[m]:.3f} ({theirs[m]:.2f})" for m in LATLON)
            lines.append(f"{label:<{lw}}{track:<{w}}" + "".join(f"{c:>20}" for c in cells))
    return "\n".join(lines)


def vehicles_table(errors: dict[int, dict[str, dict[str, float]]]) -> str:
    """A text table of each vehicle's mean error per track (m), against its own truth; a
    vehicle without a track's estimates shows "-"."""
    tracks = sorted({t for e in errors.values() for t in e})
    w = max([len("vehicle"), *map(len, tracks)]) + 2
    lines = ["mean position error per vehicle and track (m)",
             f"{'vehicle':<9}" + "".join(f"{t:>{w}}" for t in tracks)]
    for v in sorted(errors):
        lines.append(f"{v:<9}" + "".join(f"{errors[v][t]['mean']:>{w}.3f}" if t in errors[v]
                                         else f"{'-':>{w}}" for t in tracks))
    return "\n".join(lines)


def plot(truth: dict, estimates: dict, path: str | Path, offset_s: float = 0.0,
         anchors: dict | None = None) -> Path:
    """Tracks and error over time, as a PNG (needs matplotlib: the ``plot`` extra)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 5))
    ax1.plot(truth["x"], truth["y"], "k-", lw=2, label="truth")
    for name, e in sorted(estimates.items()):
        ax1.plot(e["x"], e["y"], lw=1, label=name)
        t = e["t"] + offset_s
        ax2.plot(t, error(truth, e, offset_s), lw=1, label=name)
    xs, ys = list(truth["x"]), list(truth["y"])
    if anchors:
        ax, ay = zip(*[(a[0], a[1]) for a in anchors.values()])
        ax1.plot(ax, ay, "r^", ms=9, label="anchors")
        xs += ax
        ys += ay
    # the room, not wherever a drifting track went; errors on a log scale for the same reason
    margin = 1.5
    ax1.set(xlim=(min(xs) - margin, max(xs) + margin), ylim=(min(ys) - margin, max(ys) + margin),
            xlabel="x (m)", ylabel="y (m)", title="tracks (the area; drifting tracks leave it)",
            aspect="equal")
    ax2.set(xlabel="scenario time (s)", ylabel="position error (m)", title="error", yscale="log",
            ylim=(0.01, None))
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
    handles, labels = ax1.get_legend_handles_labels()  # one legend, below: nothing hidden
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def p_text(v: float) -> str:
    """A p-value in two significant digits; "-" where there is none (NaN)."""
    return "-" if math.isnan(v) else f"{v:.2g}"


def ci_text(v: tuple[float, float], digits: int = 3) -> str:
    """A (mean, half-width) as the tables print it: "m ± h", "m" without a half-width, "-"
    without a mean."""
    m, h = v
    if math.isnan(m):
        return "-"
    return f"{m:.{digits}f}" + ("" if math.isnan(h) else f" ± {h:.{digits}f}")


def paired_differences(ok: dict, a: str, b: str, figure: str) -> list[float]:
    """Per seed both tracks have a finite *figure* of (*ok*: track -> seed -> row), a - b."""
    def has(r):
        return r.get(figure) is not None and math.isfinite(r[figure])

    return [ok[a][s][figure] - ok[b][s][figure]
            for s in sorted(set(ok[a]) & set(ok[b])) if has(ok[a][s]) and has(ok[b][s])]


#: The family-wise level at which a table's paired comparisons decide (:func:`decide`).
ALPHA = 0.05


def paired(ok: dict, a: str, b: str, figure: str) -> dict:
    """The per-seed difference a - b of *figure* over the seeds both tracks have: its mean,
    95 % t half-width and the paired t test's two-sided p; ``better`` is left to
    :func:`decide`, over the family of comparisons the table shows."""
    diffs = paired_differences(ok, a, b, figure)
    d, h = mean_ci(diffs)
    return {"a": a, "b": b, "seeds": len(diffs), "diff": d, "half": h, "p": paired_p(diffs),
            "better": None}


def decide(family: list[dict]) -> None:
    """Set ``holm_p`` and ``better`` of each comparison of *family* (:func:`paired`'s): the
    track it decides for where its Holm-adjusted p is below :data:`ALPHA`, else None. Holm
    rather than each pair's own 95 % CI: with 28 pairs at 5 % each, a table decides about
    one pair by chance when no track differs from another (and a fresh sweep of office turned
    a decided 'ekf better than kf', 3.1 +- 3.0 mm, into -1.6 +- 8.3 mm)."""
    for c, adjusted in zip(family, holm([c["p"] for c in family])):
        c["holm_p"] = adjusted
        c["better"] = (c["a"] if c["diff"] < 0 else c["b"]) if adjusted < ALPHA else None


def paired_p(diffs) -> float:
    """Two-sided p of the paired t test that the mean of *diffs* is 0 (NaN below 2 seeds or
    with every difference 0; 0 when they are all the same other value)."""
    v = np.asarray(diffs, dtype=float)
    if v.size < 2 or not v.any():
        return math.nan
    sd = v.std(ddof=1)
    if sd == 0:
        return 0.0
    return float(2 * student_t.sf(abs(v.mean()) / (sd / math.sqrt(v.size)), v.size - 1))


def holm(pvalues) -> list[float]:
    """Holm's step-down adjusted p-values of a family of *pvalues* (NaN stays NaN and counts in
    the family): the i-th smallest p times (m - i + 1), never below an earlier one, at most 1.
    A comparison is decided at family-wise level alpha when its adjusted p is below alpha: the
    same as its CI at level 1 - alpha / (m - i + 1) excluding 0, every smaller p decided first."""
    p = np.asarray(pvalues, dtype=float)
    m, out, running = p.size, np.full(p.size, math.nan), 0.0
    for i, j in enumerate(sorted(np.flatnonzero(np.isfinite(p)), key=lambda j: p[j])):
        running = max(running, min(1.0, (m - i) * p[j]))
        out[j] = running
    return out.tolist()


def mean_ci(values) -> tuple[float, float]:
    """Mean and the half-width of its two-sided 95 % Student-t interval (NaN below 2 values)."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return math.nan, math.nan
    if v.size < 2:
        return float(v.mean()), math.nan
    half = student_t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size)
    return float(v.mean()), float(half)
