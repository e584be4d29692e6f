"""The report of a lab run (``navtwin report RUN_DIR``): one self-contained HTML file and a
Markdown summary.

A run directory is what ``navtwin lab`` writes (lab.orchestrator): the emulator's recording
(``truth.csv``, ``scenario.toml``, ``faults.jsonl``, ``recording.json``), the host's
(``host/``), ``estimates.jsonl``, ``innovations.jsonl``, ``host.log`` and ``report.json``.
Only ``emulator/truth.csv``, ``emulator/scenario.toml`` and ``estimates.jsonl`` are
required; the report says what it lacks.

Every number of the accuracy tables comes from ``estimates.jsonl`` through lab.evaluate
(``position_errors`` after the run's ``time_offset_s``; the latitude/longitude figures in the
scenario's frame; the tables of the layout its paper gives, lab.layouts: 003's Table 1, 004's
Tables 2 and 3 from lab.areas's windows), the NIS
from ``innovations.jsonl``, the bound from lab.pcrb; the file hashes under "Provenance" name
the files they came from. The HTML holds its plots as inline SVG (matplotlib's svg backend)
and its style inline: no network, no script.
"""
from __future__ import annotations

import hashlib
import html
import io
import json
import re
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from navtwin.common.schema import Invalid, value
from navtwin.emulator.scenario import ScenarioError, load_scenario
from navtwin.emulator.truth import file_name as truth_file
from navtwin.host import config as host_config
from navtwin.host.config import ConfigError
from navtwin.host.replay import config_for
from navtwin.protocols.recording import FAULTS

from . import evaluate, layouts, pcrb
from .provenance import code_version

#: Table 1's rows (paper 001): key of lab.evaluate.position_errors -> label; ranges are two keys.
ROWS = (("x_range", "x error range (m)"), ("x_var", "x error variance (m²)"),
        ("y_range", "y error range (m)"), ("y_var", "y error variance (m²)"),
        ("max", "max error (m)"), ("mean", "mean error (m)"), ("rms", "RMS error (m)"),
        ("n", "estimates"), ("nees_mean", "mean NEES (2 dof)"),
        ("nees_in_band", "NEES inside its 95 % band"))
HASHED = ("estimates.jsonl", "innovations.jsonl", "host.log", "report.json",
          "emulator/truth.csv", "emulator/scenario.toml", "emulator/" + FAULTS,
          "emulator/recording.json")


class ReportError(ValueError):
    """The run directory cannot be reported on: one line naming the problem and the fix."""


def fmt(v) -> str:
    """A table's number as the report prints it (the tests compare these strings)."""
    if v is None:
        return "–"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return f"{v:.4f}"


def cell(e: dict, key: str) -> str:
    if key.endswith("_range"):
        a = key[0]
        return f"{fmt(e[a + '_min'])} … {fmt(e[a + '_max'])}"
    return fmt(e[key])


# -- reading the run ---------------------------------------------------------------------

def _json(path: Path) -> dict:
    """The JSON object in *path*, {} when there is no such file (a run stopped before writing
    it); anything else there is refused: its figures (the time offset) would be silently lost."""
    try:
        obj = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as e:
        obj = e
    if not isinstance(obj, dict):
        raise ReportError(f"{path}: not the JSON object navtwin lab writes "
                          f"({_what(obj)}); re-run navtwin lab")
    return obj


def _what(obj) -> str:
    if isinstance(obj, OSError):
        return obj.strerror or type(obj).__name__
    return "unreadable JSON" if isinstance(obj, ValueError) else f"a JSON {type(obj).__name__}"


def _jsonl(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    out = []
    for line in path.read_text(errors="replace").splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue
    return out


def _host_config(d: Path, scenario: str):
    meta = _json(d / "host" / "recording.json").get("host", {})
    try:
        if "config" in meta:
            return host_config.from_dict(meta["config"], "the host recording's config")
        name = config_for(scenario)
        return None if name is None else host_config.load(name)
    except ConfigError:
        return None


def collect(run_dir: str | Path) -> dict:
    """Everything the report shows, from the run directory's files."""
    d = Path(run_dir)
    if not d.is_dir():
        raise ReportError(f"{d}: not a directory; give the run directory of 'navtwin lab'")
    for need in ("emulator/truth.csv", "emulator/scenario.toml", "estimates.jsonl"):
        if not (d / need).is_file():
            raise ReportError(f"{d}: no {need}; give a run directory written by 'navtwin lab'")
    try:
        sc = load_scenario(d / "emulator" / "scenario.toml")
    except ScenarioError as e:
        raise ReportError(f"{d}/emulator/scenario.toml: {e}") from None
    report = _json(d / "report.json")
    car = report.get("car", 1)  # the car of the main figures: the first the hosts followed
    if not isinstance(car, int) or isinstance(car, bool) or car < 1:
        raise ReportError(f"{d}/report.json: car is not a car number; re-run navtwin lab")
    try:
        truth = evaluate.load_truth(d / "emulator" / truth_file(car))
        estimates = evaluate.load_estimates(d / "estimates.jsonl")
    except (ValueError, KeyError, IndexError, StopIteration) as e:
        raise ReportError(f"{d}: truth.csv or estimates.jsonl is not what navtwin lab writes "
                          f"({type(e).__name__}: {e}); re-run navtwin lab") from None
    if not estimates:
        raise ReportError(f"{d}/estimates.jsonl: no estimate; the host wrote none (see host.log)")
    offset = report.get("time_offset_s", 0.0)
    try:
        value(offset, float, "time_offset_s")
    except Invalid as e:
        raise ReportError(f"{d}/report.json: {e}; re-run navtwin lab") from None
    for key in ("emulator", "audit"):
        if not isinstance(report.get(key, {}), dict):
            raise ReportError(f"{d}/report.json: {key} is not the JSON object navtwin lab "
                              "writes; re-run navtwin lab")
    logs = _jsonl(d / "host.log")
    summaries = [x["summary"] for x in logs if "summary" in x]
    recording = _json(d / "emulator" / "recording.json")
    cfg = _host_config(d, sc.name)
    run = {"dir": str(d), "scenario": sc, "car": car, "truth": truth, "estimates": estimates,
           "offset_s": offset,
           "errors": evaluate.position_errors(truth, estimates, offset, frame=sc.frame),
           "innovations": _jsonl(d / "innovations.jsonl") if (d / "innovations.jsonl").is_file()
           else None,
           "host_summary": summaries[-1] if summaries else None, "recording": recording,
           "emulator": report.get("emulator"), "faults": _jsonl(d / "emulator" / FAULTS),
           "audit": report.get("audit"), "host_config": cfg,
           "paper": evaluate.PAPER_FIGURES.get(sc.name),
           "hashes": {n: hashlib.sha256((d / n).read_bytes()).hexdigest()
                      for n in HASHED if (d / n).is_file()},
           "code": code_version()}
    run["tables"] = layout_tables(run)
    run["vehicles"] = _vehicles(d, report.get("vehicles"), sc)
    if cfg is not None:
        ec = cfg.estimator_config()
        run["bound"] = pcrb.position_bound(sc, truth, ec.jerk_psd, ec.p0_sigma)
        run["bound_model"] = {"jerk_psd": ec.jerk_psd, "p0_sigma": list(ec.p0_sigma)}
    return run


#: the files report.json's ``vehicles`` may name (lab.orchestrator): nothing outside the run
_VEHICLE_FILES = re.compile(r"emulator/truth[0-9]*\.csv|estimates[0-9]*\.jsonl")


def _vehicles(d: Path, followed, sc) -> dict[int, dict]:
    """Each car of a lab of several (report.json's ``vehicles``): its truth, its estimates
    and its errors per track against its own truth; {} for a one-vehicle lab."""
    if not followed:
        return {}
    out = {}
    try:
        for v, f in sorted(followed.items(), key=lambda kv: int(kv[0])):
            if not all(_VEHICLE_FILES.fullmatch(f[k]) for k in ("truth", "estimates")):
                raise ValueError(f"names {f['truth']!r} and {f['estimates']!r}")
            truth = evaluate.load_truth(d / f["truth"])
            est = evaluate.load_estimates(d / f["estimates"], vehicle=int(f["host_vehicle"]))
            off = value(f["time_offset_s"], float, "time_offset_s")
            out[int(v)] = {"truth": truth, "estimates": est, "offset_s": off,
                           "errors": evaluate.position_errors(truth, est, off, frame=sc.frame)}
    except (ValueError, KeyError, TypeError, AttributeError, OSError, Invalid) as e:
        raise ReportError(f"{d}/report.json: vehicles is not what navtwin lab writes "
                          f"({type(e).__name__}: {e}); re-run navtwin lab") from None
    return out


def vehicle_rows(run: dict) -> tuple[list[str], list[tuple[str, ...]]]:
    """The cars' table: per car, each track's mean (max) error against its own truth, m."""
    tracks = sorted({t for v in run["vehicles"].values() for t in v["errors"]})
    rows = [(str(n), *(f"{fmt(v['errors'][t]['mean'])} ({fmt(v['errors'][t]['max'])})"
                       if t in v["errors"] else "-" for t in tracks))
            for n, v in run["vehicles"].items()]
    return ["car", *tracks], rows


def nees_series(run: dict) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per filter with a covariance: scenario time and NEES of each estimate inside the truth."""
    out = {}
    truth, off = run["truth"], run["offset_s"]
    for name, e in sorted(run["estimates"].items()):
        t = e["t"] + off
        keep = (t >= truth["t"][0]) & (t <= truth["t"][-1])
        q = evaluate.nees(evaluate.axis_errors(truth, e, off)[keep], e["cov"][keep])
        if np.isfinite(q).any():
            out[name] = (t[keep], q)
    return out


# -- figures -----------------------------------------------------------------------------

def _svg(fig, name: str) -> str:
    import matplotlib.pyplot as plt

    buf = io.StringIO()
    with plt.rc_context({"svg.hashsalt": name}):  # ids unique among the page's figures
        fig.savefig(buf, format="svg", metadata={"Date": None})
    plt.close(fig)
    text = buf.getvalue()
    # inline: no XML declaration, DOCTYPE or RDF metadata (they name URLs)
    return re.sub(r"<metadata>.*?</metadata>\s*", "", text[text.index("<svg"):], flags=re.S)


def _grid(n: int, size=(4.2, 3.2), cols: int = 3):
    import matplotlib.pyplot as plt

    cols = min(cols, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(size[0] * cols, size[1] * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()[:n]


def figures(run: dict) -> dict[str, str]:
    """name -> inline SVG of each plot."""
    import matplotlib

    matplotlib.use("Agg")
    truth, sc, off = run["truth"], run["scenario"], run["offset_s"]
    names = sorted(run["estimates"])
    palette = [f"C{i}" for i in range(10) if i != 3]  # C3 is the anchors' red
    colours = {n: palette[i % len(palette)] for i, n in enumerate(names)}
    out = {}
    # the tracks, one panel each (000's and 001's trajectory figures), on the room's extent
    anchors = np.array([sc.anchor_position(a)[:2] for a in sc.all_anchors])
    xs = np.concatenate((truth["x"], anchors[:, 0]))
    ys = np.concatenate((truth["y"], anchors[:, 1]))
    margin = 1.0
    ratio = (np.ptp(ys) + 2 * margin) / (np.ptp(xs) + 2 * margin)
    fig, axes = _grid(len(names), (4.2, 4.2 * min(1.2, max(0.3, ratio)) + 1.1))
    for ax, n in zip(axes, names):
        e = run["estimates"][n]
        ax.plot(truth["x"], truth["y"], "k-", lw=1.5, label="truth")
        ax.plot(e["x"], e["y"], "-", color=colours[n], lw=1, label=n, gid=f"track-{n}")
        ax.plot(anchors[:, 0], anchors[:, 1], "r^", ms=8, label="anchors")
        ax.set(xlim=(xs.min() - margin, xs.max() + margin), ylim=(ys.min() - margin, ys.max() + margin),
               aspect="equal", title=n, xlabel="x (m)", ylabel="y (m)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0, -0.22), ncol=3, frameon=False)
    fig.tight_layout()
    out["tracks"] = _svg(fig, "tracks")
    if run["vehicles"]:  # each car's truth and its best track, one panel a car
        fig, axes = _grid(len(run["vehicles"]), (4.2, 4.2 * min(1.2, max(0.3, ratio)) + 1.1))
        for ax, (v, car) in zip(axes, run["vehicles"].items()):
            if not car["errors"]:
                ax.set_title(f"car {v}: no estimates")
                continue
            best = min(car["errors"], key=lambda t: car["errors"][t]["mean"])
            e = car["estimates"][best]
            ax.plot(car["truth"]["x"], car["truth"]["y"], "k-", lw=1.5, label="truth")
            ax.plot(e["x"], e["y"], "-", color=colours.get(best, "C0"), lw=1, label=best,
                    gid=f"car-{v}")
            ax.plot(anchors[:, 0], anchors[:, 1], "r^", ms=8, label="anchors")
            ax.set(xlim=(xs.min() - margin, xs.max() + margin), ylim=(ys.min() - margin, ys.max() + margin),
                   aspect="equal", title=f"car {v}: {best}, mean {fmt(car['errors'][best]['mean'])} m",
                   xlabel="x (m)", ylabel="y (m)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0, -0.22), ncol=3, frameon=False)
        fig.tight_layout()
        out["cars"] = _svg(fig, "cars")

    # the error, one small panel per track on one scale: overlaid, pairs that agree hid each other
    errors = {n: evaluate.error(truth, run["estimates"][n], off) for n in names}
    top = max(1.0, *(float(np.nanmax(v)) for v in errors.values() if v.size)) * 1.5
    fig, axes = _grid(len(names), (4.2, 2.6))
    for ax, n in zip(axes, names):
        ax.plot(run["estimates"][n]["t"] + off, errors[n], lw=1, color=colours[n], label=n,
                gid=f"error-{n}")
        if "bound" in run:
            b = run["bound"]
            ax.plot(b["t"], b["rms"], "k--", lw=1, label="PCRB (RMS, ranges only)",
                    gid="pcrb" if n == names[0] else f"pcrb-{n}")
        ax.set(yscale="log", ylim=(0.005, top), title=n, xlabel="scenario time (s)",
               ylabel="error (m)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    out["error"] = _svg(fig, "error")

    # 003's Figures 4-6: latitude and longitude error against time
    if evaluate.latlon_rows(sc.name, run["errors"]):
        fig, axes = _grid(len(names), (4.2, 2.6))
        for ax, n in zip(axes, names):
            e = run["estimates"][n]
            ne = evaluate.north_east_errors(sc.frame, truth, e, off)
            ax.plot(e["t"] + off, ne[:, 0], lw=1, color=colours[n], label="latitude (north)",
                    gid=f"lat-{n}")
            ax.plot(e["t"] + off, ne[:, 1], lw=1, color=colours[n], ls="--",
                    label="longitude (east)", gid=f"lon-{n}")
            ax.axhline(0.0, color="0.4", lw=0.6)
            ax.set(title=n, xlabel="scenario time (s)", ylabel="error (m)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper left")
        fig.tight_layout()
        out["latlon"] = _svg(fig, "latlon")

    series = nees_series(run)
    if series:
        lo, hi = evaluate.NEES_BAND_95
        fig, axes = _grid(len(series), (5.5, 3.0), cols=2)
        for ax, (n, (t, q)) in zip(axes, series.items()):
            ax.plot(t, q, ".", ms=2, color=colours[n], gid=f"nees-{n}")
            ax.axhspan(lo, hi, color="0.85", zorder=0, label="95 % band, 2 dof")
            ax.axhline(2.0, color="0.4", lw=0.8)
            ax.set(yscale="log", title=f"{n}: NEES", xlabel="scenario time (s)", ylabel="NEES")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper right")
        fig.tight_layout()
        out["nees"] = _svg(fig, "nees")

    if run["innovations"]:
        by = nis_series(run)
        fig, axes = _grid(len(by), (5.5, 3.0), cols=2)
        for ax, (n, kinds) in zip(axes, by.items()):
            for kind, (dim, t, q, ok) in sorted(kinds.items()):
                c = kind_colour(kind)
                ax.plot(t[ok], q[ok], ".", ms=2, color=c, label=f"{kind} ({dim} dof)",
                        gid=f"nis-{n}-{kind}")
                ax.plot(t[~ok], q[~ok], "x", ms=4, color=c)
                lo, hi = chi2.ppf([0.025, 0.975], dim)
                ax.hlines([lo, hi], t.min(), t.max(), colors=c, linestyles="--", lw=0.8)
            ax.set(yscale="log", title=f"{n}: NIS (×: gated out)", xlabel="scenario time (s)",
                   ylabel="NIS", ylim=(NIS_FLOOR, None))
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper right", markerscale=3)
        fig.tight_layout()
        out["nis"] = _svg(fig, "nis")
    return out


#: the NIS plots' lower edge: the at-rest updates of the alignment (NIS ~1e-8) lie below it
NIS_FLOOR = 1e-3
_KINDS = ("accel", "fix", "tdoa", "range", "stationary")


def kind_colour(kind: str) -> str:
    """One colour per update kind on every filter's NIS plot (tdoa/2 as tdoa)."""
    base = kind.split("/")[0]
    return f"C{_KINDS.index(base)}" if base in _KINDS else "C7"


def nis_series(run: dict) -> dict[str, dict[str, tuple]]:
    """filter -> kind -> (dim, scenario time, NIS, accepted) of vehicle 1's innovations."""
    rows: dict = {}
    for r in run["innovations"] or ():
        if r.get("vehicle", 1) == 1:
            rows.setdefault(r["filter"], {}).setdefault((r["kind"], r["dim"]), []).append(
                (r["t"] + run["offset_s"], r["nis"], r["accepted"]))
    out: dict = {}
    for n in sorted(rows):
        dims = Counter(kind for kind, _ in rows[n])  # a kind of several dimensions (TDOA with
        for (kind, dim), v in sorted(rows[n].items()):  # an anchor out): one entry each
            a = np.array(v, dtype=float)
            out.setdefault(n, {})[kind if dims[kind] == 1 else f"{kind}/{dim}"] = (
                int(dim), a[:, 0], a[:, 1], a[:, 2].astype(bool))
    return out


def _without_innovation(q: np.ndarray) -> bool:
    """A kind whose every NIS lies below the plots' edge: the alignment's at-rest updates,
    whose innovation is nought by construction, so their NIS says nothing of consistency."""
    return bool((q < NIS_FLOOR).all())


def nis_table(run: dict) -> list[tuple]:
    """(filter, kind, dim, updates, mean NIS, share inside the 95 % band, gated out); kinds
    without innovations are in :func:`nis_left_out` instead."""
    out = []
    for n, kinds in nis_series(run).items():
        for kind, (dim, _, q, ok) in kinds.items():
            if _without_innovation(q):
                continue
            lo, hi = chi2.ppf([0.025, 0.975], dim)
            out.append((n, kind, dim, len(q), float(q.mean()), float(((q >= lo) & (q <= hi)).mean()),
                        int((~ok).sum())))
    return out


def nis_left_out(run: dict) -> str:
    """The note under the NIS table naming the kinds it leaves out, or ''."""
    left: dict[str, int] = {}
    for kinds in nis_series(run).values():
        for kind, (_, _, q, _) in kinds.items():
            if _without_innovation(q):
                left[kind] = left.get(kind, 0) + q.size
    if not left:
        return ""
    return ("Left out: " + ", ".join(f"{k} ({n} updates)" for k, n in sorted(left.items())) +
            f", whose every NIS is below {NIS_FLOOR:g}: the alignment's at-rest updates, whose "
            "innovation is nought by construction, so their NIS says nothing of consistency.")


# -- tables ------------------------------------------------------------------------------

def accuracy_rows(run: dict) -> list[tuple[str, str, list[tuple[str, str]]]]:
    """(key, label, [(filter, text)]) per Table 1 row, then the paper's figures as rows of
    their own (key ``paper:<key>``) where the scenario's paper has any."""
    errors, paper = run["errors"], run["paper"]
    rows = []
    for key, label in ROWS:
        rows.append((key, label, [(n, cell(e, key)) for n, e in errors.items()]))
        if paper and any(key in v for v in paper["figures"].values()):
            rows.append((f"paper:{key}", f"{label}, paper {paper['paper']}",
                         [(n, fmt(paper["figures"].get(n, {}).get(key))) for n in errors]))
    return rows


def layout_tables(run: dict) -> list[dict]:
    """The tables of the layout the scenario's paper gives (lab.layouts: 003's latitude and
    longitude, 004's training areas and outages), each a dict of ``title``, ``head``, ``rows``
    (two name columns, then numbers; a paper's own row has no track), ``stats`` (the figures'
    keys, for the HTML's data attributes, or None) and ``note``; [] for any other scenario."""
    layout = layouts.of(run["scenario"].name)
    return layout[1].report_tables(run) if layout else []


def _cells(table: dict) -> list[tuple[str, ...]]:
    """A layout table's rows as text: its two name columns, then each number through fmt."""
    return [(*r[:2], *(fmt(v) for v in r[2:])) for r in table["rows"]]


def link_rows(run: dict) -> list[tuple[str, ...]]:
    """Per port: the emulator's frames and bytes written, the host's frames, bytes and errors."""
    s, emu = run["host_summary"] or {}, (run["emulator"] or {}).get("ports", {})
    ports = sorted(set(emu) | set(s.get("ports", {})))
    out = []
    for p in ports:
        e, h = emu.get(p, {}), s.get("ports", {}).get(p, {})
        errors = h.get("errors", {})
        out.append((p, fmt(e.get("frames")), fmt(e.get("bytes")), fmt(h.get("frames")),
                    fmt(h.get("bytes")),
                    ", ".join(f"{k} {v}" for k, v in sorted(errors.items())) or ("0" if h else "–")))
    return out


def fault_rows(run: dict) -> list[tuple[str, ...]]:
    """Per fault kind: injections, ports, first and last device time (s)."""
    by: dict[str, list] = {}
    for f in run["faults"]:
        by.setdefault(f.get("kind", "?"), []).append(f)
    return [(k, str(len(v)), ", ".join(sorted({str(f.get("port")) for f in v})),
             fmt(min(f.get("t_ns", 0) for f in v) / 1e9), fmt(max(f.get("t_ns", 0) for f in v) / 1e9))
            for k, v in sorted(by.items())]


def provenance(run: dict) -> list[tuple[str, str]]:
    sc, rec = run["scenario"], run["recording"]
    rows = [("scenario", f"{sc.name}: {sc.description}"), ("seed", str(rec.get("seed", sc.seed))),
            ("duration (s)", str(rec.get("virtual_s", rec.get("duration_s", "–")))),
            ("speed", str(rec.get("speed", "–"))), ("code", run["code"]),
            ("host config", run["host_config"].name if run["host_config"] else "–"),
            ("host time offset (s)", f"{run['offset_s']:.6f}")]
    rows += [(f"sha256 {n}", h) for n, h in run["hashes"].items()]
    return rows


def _counts(run: dict) -> list[tuple[str, str]]:
    s = run["host_summary"]
    if not s:
        return []
    c = s.get("counts", {})
    keys = ("imu", "reports", "ranges", "timeouts", "range_errors", "reports_lost",
            "reports_duplicate", "ranges_late", "db_answers")
    rows = [(k, str(c.get(k, 0))) for k in keys]
    rows += [("max late range (ms)", fmt(s.get("max_late_ms"))), ("link (dBm)", str(s.get("link_dbm"))),
             ("reconnects", ", ".join(f"{k} {v}" for k, v in s.get("reconnects", {}).items())
              or "–"),
             ("host latency (ms)", _latency(s.get("latency") or {}))]
    return rows


def _latency(lat: dict) -> str:
    """The host's read-to-estimate latency: p50, p99 and max in ms, over n estimates."""
    if not lat.get("n"):
        return "–"
    return (f"p50 {lat['p50_ms']:.3f}, p99 {lat['p99_ms']:.3f}, max {lat['max_ms']:.3f} "
            f"(n {lat['n']})")


def paper_note(run: dict) -> str:
    """What the paper's figures are of, and whether this run is long enough to set beside
    them: their experiment's duration against the scenario time this run covers."""
    paper = run["paper"]
    if not paper:
        return ""
    run_s = float(run["truth"]["t"][-1] - run["truth"]["t"][0])
    text = (f"Paper {paper['paper']}: {paper['note']}. Its experiment: {paper['experiment']}, "
            f"{paper['duration_s']:g} s.")
    if run_s < SHORT_RUN * paper["duration_s"]:
        text += (f" This run covers {run_s:.1f} s of it, too short to set beside those figures "
                 "as equals: they are of the whole experiment, and errors that grow with time "
                 "(the SINS drift, a bias) have not grown as far here.")
    return text


#: A run that covers less than this share of its paper's experiment is said to be too short.
SHORT_RUN = 0.95


# -- output ------------------------------------------------------------------------------

def _md_table(head, rows) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def markdown(run: dict) -> str:
    names = list(run["errors"])
    sc = run["scenario"]
    parts = [f"# navtwin report: {sc.name}, seed {run['recording'].get('seed', sc.seed)}", "",
             f"Run directory `{run['dir']}`; the plots are in report.html.", "",
             "## Accuracy (paper 001 Table 1's layout)", "",
             _md_table(["statistic", *names], [(label, *(t for _, t in cells))
                                               for _, label, cells in accuracy_rows(run)])]
    for t in run["tables"]:
        parts += ["", f"## {t['title']}", "", _md_table(t["head"], _cells(t)), "", t["note"]]
    if run["vehicles"]:
        parts += ["", "## Cars: each car's error against its own truth, mean (max), m", "",
                  _md_table(*vehicle_rows(run)), "", f"The accuracy above is car {run['car']}'s."]
    if paper_note(run):
        parts += ["", paper_note(run)]
    if "bound" in run:
        b = run["bound"]
        parts += ["", f"Posterior Cramer-Rao bound (ranges only, docs/report.md): RMS position "
                      f"{fmt(float(np.median(b['rms'])))} m median, {fmt(float(b['rms'][-1]))} m "
                      "at the end."]
    if run["innovations"] is not None:
        parts += ["", "## Innovations (NIS)", "",
                  _md_table(["filter", "kind", "dof", "updates", "mean NIS", "inside 95 %",
                             "gated out"], [(n, k, d, u, fmt(m), fmt(b), g)
                                            for n, k, d, u, m, b, g in nis_table(run)])]
        if nis_left_out(run):
            parts += ["", nis_left_out(run)]
    parts += ["", "## Link and ranging", "",
              _md_table(["port", "emulator frames", "emulator bytes", "host frames", "host bytes",
                         "host errors"], link_rows(run))]
    if _counts(run):
        parts += ["", _md_table(["host count", "value"], _counts(run))]
    parts += ["", "## Faults injected", ""]
    parts += [_md_table(["kind", "injections", "ports", "first (s)", "last (s)"], fault_rows(run))
              if run["faults"] else "None (the ledger is empty)."]
    if run["audit"]:
        parts += ["", f"Audit: {_audit_text(run['audit'])}"]
    parts += ["", "## Provenance", "", _md_table(["", ""], provenance(run)), ""]
    return "\n".join(parts)


def _audit_text(a: dict) -> str:
    if "error" in a:
        return f"not possible: {a['error']}"
    problems = [p for r in a.get("ports", {}).values() for p in r.get("problems", [])]
    return ("PASS: every intact frame accepted, every rejected byte injected" if not problems
            else f"FAIL, {len(problems)} problem(s): " + "; ".join(problems[:5]))


CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:24px auto;max-width:1240px;
color:#1d232b;background:#fff}
h1{font-size:1.6em;margin-bottom:.2em}h2{font-size:1.2em;margin-top:1.6em;border-bottom:2px solid #d8dee6}
.sub{color:#5a6573}table{border-collapse:collapse;margin:.6em 0;font-size:.92em}
th,td{border:1px solid #d8dee6;padding:4px 10px;text-align:right}th{background:#eef2f7}
td:first-child,th:first-child{text-align:left}tr.paper td{color:#5a6573;font-style:italic}
.fig svg{max-width:100%;height:auto}.note{color:#5a6573;font-size:.9em;max-width:900px}
code{background:#f3f5f8;padding:0 3px}
"""


def _html_table(head, rows, attrs=None, classes=None) -> str:
    e = html.escape
    out = ["<table><tr>" + "".join(f"<th>{e(str(h))}</th>" for h in head) + "</tr>"]
    for i, r in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes and classes[i] else ""
        tds = []
        for j, c in enumerate(r):
            a = attrs(i, j) if attrs else ""
            tds.append(f"<td{a}>{e(str(c))}</td>")
        out.append(f"<tr{cls}>" + "".join(tds) + "</tr>")
    return "".join(out) + "</table>"


def html_page(run: dict, figs: dict[str, str]) -> str:
    e = html.escape
    names = list(run["errors"])
    sc = run["scenario"]
    acc = accuracy_rows(run)

    def acc_attr(i, j):
        return "" if j == 0 else f' data-stat="{acc[i][0]}" data-filter="{acc[i][2][j - 1][0]}"'

    body = [f"<h1>navtwin report: {e(sc.name)}, seed {e(str(run['recording'].get('seed', sc.seed)))}</h1>",
            f"<p class=sub>{e(sc.description)}. Run directory <code>{e(run['dir'])}</code>.</p>",
            "<h2>Tracks over truth and anchors</h2>", f"<div class=fig id=fig-tracks>{figs['tracks']}</div>",
            "<h2>Error against time</h2>", f"<div class=fig id=fig-error>{figs['error']}</div>"]
    if "bound" in run:
        m = run["bound_model"]
        body.append(f"<p class=note>Dashed: the posterior Cramer-Rao bound (Tichavsky et al. 1998) "
                    f"of the fusion tracks' constant-acceleration model (jerk PSD {m['jerk_psd']:g} "
                    "m²/s⁵) with the scenario's ranges only, at the true positions, the emulator's "
                    "range noise; the tracks also use the SINS acceleration, so they may go below "
                    "it (docs/report.md).</p>")
    body += ["<h2>Accuracy (paper 001 Table 1's layout)</h2>",
             _html_table(["statistic", *names], [(label, *(t for _, t in cells)) for _, label, cells in acc],
                         acc_attr, ["paper" if k.startswith("paper:") else "" for k, _, _ in acc])]
    for t in run["tables"]:
        rows, stats = _cells(t), t["stats"]

        def attrs(i, j, rows=rows, stats=stats):
            return ("" if stats is None or j < 2 or not rows[i][1] else
                    f' data-stat="{stats[j - 2]}" data-filter="{rows[i][1]}"')

        body += [f"<h2>{e(t['title'], quote=False)}</h2>",
                 _html_table(t["head"], rows, attrs, ["" if r[1] else "paper" for r in rows]),
                 f"<p class=note>{e(t['note'])}</p>"]
    if run["vehicles"]:
        body += ["<h2>Cars: each car's error against its own truth, mean (max), m</h2>",
                 f"<p class=note>The figures and tables above are car {run['car']}'s; each panel below is "
                 "a car's truth and its best track.</p>",
                 _html_table(*vehicle_rows(run)), f"<div class=fig id=fig-cars>{figs['cars']}</div>"]
    if "latlon" in figs:
        body += ["<h2>Latitude and longitude error against time</h2>",
                 f"<div class=fig id=fig-latlon>{figs['latlon']}</div>"]
    if paper_note(run):
        body.append(f"<p class=note id=paper-note>{e(paper_note(run))}</p>")
    if "nees" in figs:
        body += ["<h2>NEES against its chi-square band</h2>",
                 "<p class=note>e<sup>T</sup>P<sup>-1</sup>e of each estimate's position error "
                 "against its own covariance; grey: the two-sided 95 % band of chi-square with 2 "
                 "degrees of freedom; line: its mean, 2.</p>",
                 f"<div class=fig id=fig-nees>{figs['nees']}</div>"]
    if "nis" in figs:
        body += ["<h2>NIS against chi-square bands</h2>",
                 "<p class=note>Each gated update's y<sup>T</sup>S<sup>-1</sup>y; dashed: the 95 % "
                 "band of chi-square with the measurement's dimension. The at-rest updates of the "
                 f"alignment (stationary) fall below the plots' {NIS_FLOOR:g} edge; the table "
                 "has them all.</p>",
                 f"<div class=fig id=fig-nis>{figs['nis']}</div>",
                 _html_table(["filter", "kind", "dof", "updates", "mean NIS", "inside 95 %", "gated out"],
                             [(n, k, d, u, fmt(m), fmt(b), g) for n, k, d, u, m, b, g in nis_table(run)])]
        if nis_left_out(run):
            body.append(f"<p class=note>{e(nis_left_out(run))}</p>")
    elif run["innovations"] is None:
        body.append("<p class=note>No innovations.jsonl in this run: no NIS.</p>")
    body += ["<h2>Link and ranging</h2>",
             _html_table(["port", "emulator frames", "emulator bytes", "host frames", "host bytes",
                          "host errors"], link_rows(run))]
    if _counts(run):
        body.append(_html_table(["host count", "value"], _counts(run)))
    body.append("<h2>Faults injected</h2>")
    body.append(_html_table(["kind", "injections", "ports", "first (s)", "last (s)"], fault_rows(run))
                if run["faults"] else "<p>None (the ledger is empty).</p>")
    if run["audit"]:
        body.append(f"<p>Audit: {e(_audit_text(run['audit']))}</p>")
    body += ["<h2>Provenance</h2>", _html_table(["", ""], provenance(run))]
    return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<title>navtwin report: {e(sc.name)}</title><style>{CSS}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


def write_report(run_dir: str | Path, out: str | Path | None = None) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` of *run_dir* into *out* (default: the run
    directory); their paths. Needs matplotlib (the ``plot`` extra)."""
    run = collect(run_dir)
    out = Path(run_dir if out is None else out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ReportError(f"out: {out}: {e.strerror}; choose a writable directory") from None
    paths = {"html": out / "report.html", "md": out / "report.md"}
    try:
        paths["html"].write_text(html_page(run, figures(run)), encoding="utf-8")
        paths["md"].write_text(markdown(run), encoding="utf-8")
    except OSError as e:
        raise ReportError(f"out: {out}: {e.strerror}; choose a writable directory") from None
    return paths
