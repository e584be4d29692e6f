"""Latitude/longitude scoring (paper 003's Table 1): north/east errors through the scenario's
local frame, the per-run statistics against numpy, and 003's layout in the sweep's tables."""
from __future__ import annotations

import math
import re

import numpy as np
import pyarrow.parquet as pq
import pytest

from navtwin.common.geodesy import LocalFrame
from navtwin.lab import evaluate, sweep


def _xy(north, east, azimuth_deg):
    """Local x, y of a displacement *north*, *east* (m) in an area whose +x is at
    *azimuth_deg* (common.geodesy's docstring: x = e sin A + n cos A, y = -e cos A + n sin A)."""
    a = math.radians(azimuth_deg)
    return east * math.sin(a) + north * math.cos(a), -east * math.cos(a) + north * math.sin(a)


def _run(truth_xy, offsets):
    """A truth standing at *truth_xy* for 10 s, and one track's estimates at 1 Hz displaced by
    *offsets* (N x 2, local x, y)."""
    t = np.arange(len(offsets), dtype=float)
    truth = {"t": np.arange(0.0, len(offsets) + 1, 0.001)}
    truth["x"] = np.full(truth["t"].size, truth_xy[0])
    truth["y"] = np.full(truth["t"].size, truth_xy[1])
    e = {"t": t, "x": truth_xy[0] + offsets[:, 0], "y": truth_xy[1] + offsets[:, 1]}
    return truth, e


@pytest.mark.parametrize("azimuth", [30.0, 90.0, 0.0, 247.0])
def test_north_and_east_errors_follow_the_areas_azimuth(azimuth):
    """3 m north and 4 m east of the truth, written in the local x, y of an area whose x is at
    *azimuth*: 003's latitude error is the 3 m, its longitude error the 4 m, wherever x points
    (near the origin to the plane's curvature, s^2 / 2R; 1.5 km away to the meridians'
    convergence over that distance, s / R of the error)."""
    frame = LocalFrame(32.0, 118.0, 0.0, azimuth)
    dx, dy = _xy(3.0, 4.0, azimuth)
    for where, tol in (((1.0, -2.0), 1e-5), ((300.0, 1500.0), 2e-3)):
        truth, e = _run(where, np.tile([dx, dy], (5, 1)))
        ne = evaluate.north_east_errors(frame, truth, e)
        assert ne == pytest.approx(np.tile([3.0, 4.0], (5, 1)), abs=tol), where


def test_the_azimuth_changes_which_way_an_error_points():
    """The same x, y error is north in an area whose x points north, east where x points east."""
    truth, e = _run((0.0, 0.0), np.array([[2.0, 0.0]]))
    assert evaluate.north_east_errors(LocalFrame(32, 118, 0, 0), truth, e) == \
        pytest.approx(np.array([[2.0, 0.0]]), abs=1e-6)
    assert evaluate.north_east_errors(LocalFrame(32, 118, 0, 90), truth, e) == \
        pytest.approx(np.array([[0.0, 2.0]]), abs=1e-6)


def test_the_statistics_are_mean_and_max_of_the_absolute_and_std_of_the_signed_error():
    ne = np.random.default_rng(2).normal([0.5, -1.0], [2.0, 3.0], (500, 2))
    got = evaluate.latlon_figures(ne)
    assert list(got) == list(evaluate.LATLON)
    for i, axis in enumerate(("lat", "lon")):
        v = ne[:, i]
        assert got[f"{axis}_mean"] == pytest.approx(np.mean(np.abs(v)), rel=1e-12)
        assert got[f"{axis}_max"] == pytest.approx(np.max(np.abs(v)), rel=1e-12)
        assert got[f"{axis}_std"] == pytest.approx(np.std(v), rel=1e-12)


def test_position_errors_score_latitude_and_longitude_given_the_frame():
    """Known north/east errors written into an area with x at 120 deg come back as 003's
    figures; without a frame the figures are not there."""
    rng = np.random.default_rng(8)
    ne = rng.normal(0, 1.5, (60, 2))
    offsets = np.array([_xy(n, e, 120.0) for n, e in ne])
    truth, e = _run((4.0, 7.0), offsets)
    frame = LocalFrame(32.0, 118.0, 0.0, 120.0)
    got = evaluate.position_errors(truth, {"wcl": e}, frame=frame)["wcl"]
    want = evaluate.latlon_figures(ne)
    assert {k: got[k] for k in evaluate.LATLON} == pytest.approx(want, abs=1e-5)
    assert not set(evaluate.LATLON) & set(evaluate.position_errors(truth, {"wcl": e})["wcl"])


def _rows(filters, seeds=6):
    rng = np.random.default_rng(11)
    scale = {"sins": 20.0, "geosins": 15.0, "centroid": 3.0, "wcl": 1.5}
    return [sweep._row("rssi-centroid", seed, f,
                       {m: float(rng.uniform(0.5, 1.0) * scale[f]) for m in sweep.METRICS})
            for f in filters for seed in range(seeds)]


def test_the_sweep_shows_003_table_1_with_its_figures_and_the_paired_intervals():
    filters = ("sins", "centroid", "wcl")
    rows = _rows(filters)
    s = sweep.summarise(rows, filters, "rssi-centroid")
    md = sweep.markdown(s, "rssi-centroid")
    head = ("| 003 Table 1 | track | seeds | latitude average m | longitude average m | latitude max m "
            "| longitude max m | latitude std m | longitude std m |")
    assert head in md
    lines = md.splitlines()
    table = lines[lines.index(head) + 2:lines.index(head) + 5]
    assert [r.split(" | ")[:3] for r in table] == [["| Single SINS", "sins", "6"],
                                                   ["| centroid (traditional method)", "centroid", "6"],
                                                   ["| weighted centroid (003's method)", "wcl", "6"]]
    paper = evaluate.PAPER_FIGURES["rssi-centroid"]["figures"]
    m, h = sweep.mean_ci([r["lon_std"] for r in rows if r["filter"] == "wcl"])
    assert table[2].endswith(f"| {m:.3f} ± {h:.3f} ({paper['wcl']['lon_std']:.4f}) |")
    assert "(13.5977)" in table[0] and "(1.6007)" in table[1]
    # wcl against centroid, then each against the SINS alone, per figure
    pairs = [line.split(" | ")[0] for line in lines if re.match(r"\| \w+ - \w+ \| 6 \| -?\d", line)
             and line.count("|") == 9]
    assert pairs == ["| wcl - centroid", "| wcl - sins", "| centroid - sins"]
    d = [a["lat_max"] - b["lat_max"] for a, b in zip([r for r in rows if r["filter"] == "wcl"],
                                                     [r for r in rows if r["filter"] == "sins"])]
    pair = next(p for p in s["latlon"]["pairs"] if (p["a"], p["b"]) == ("wcl", "sins"))
    assert (pair["lat_max"]["diff"], pair["lat_max"]["half"]) == pytest.approx(sweep.mean_ci(d))
    assert pair["lat_max"]["better"] == "wcl"  # 1.5 against 20 m: decided
    text = sweep.table(s)
    assert re.search(r"^003 Table 1\s+track\s+seeds\s+latitude average m", text, re.M)
    assert re.search(r"^weighted centroid \(003's method\)\s+wcl\s+6\s", text, re.M)
    # no 003 Table 1 for another scenario, nor a paper column of means it does not have
    assert "latlon" not in sweep.summarise(rows, filters, "office")
    assert "003 mean m" not in md


def test_the_free_geodetic_sins_is_003s_single_sins_where_a_run_has_it():
    filters = ("sins", "geosins", "centroid", "wcl")
    s = sweep.summarise(_rows(filters), filters, "rssi-centroid")
    assert [(r["label"], r["track"]) for r in s["latlon"]["rows"]][0] == ("Single SINS", "geosins")
    assert evaluate.latlon_rows("rssi-centroid", ("wcl", "sins")) == [
        ("Single SINS", "sins", "geosins"), ("weighted centroid (003's method)", "wcl", "wcl")]


def test_a_tiny_rssi_centroid_sweep_keeps_the_figures_in_its_parquet(tmp_path):
    result = sweep.run("rssi-centroid", (1, 2), ("sins", "centroid", "wcl"), duration=20.0,
                       serial=True, out=tmp_path / "p")
    table = pq.ParquetFile(result.part).read()
    assert set(evaluate.LATLON) <= set(table.column_names)
    assert all(table.column(m).null_count == 0 for m in evaluate.LATLON)
    s = sweep.summarise(result.rows, result.filters, "rssi-centroid")
    assert [r["track"] for r in s["latlon"]["rows"]] == ["sins", "centroid", "wcl"]
    assert "| 003 Table 1 | track | seeds |" in sweep.markdown(s, "rssi-centroid", result.meta)


def test_the_report_shows_003_table_1_and_the_latitude_longitude_error_plot(tmp_path):
    """A short rssi-centroid run directory: the report's latitude/longitude table has each of
    003's rows with our figures recomputed from estimates.jsonl and the paper's below, and a
    plot of both errors against time per track (003's Figures 4-6)."""
    pytest.importorskip("matplotlib")
    from navtwin.emulator.runner import Emulation
    from navtwin.emulator.scenario import load_scenario
    from navtwin.host.output import estimate_line
    from navtwin.lab.report import write_report
    from navtwin.lab.run import run_in_memory

    sc, filters = load_scenario("rssi-centroid"), ("sins", "centroid", "wcl")
    with Emulation(sc, 4, speed=None, duration_s=15.0, ports=False,
                   record=tmp_path / "emulator") as emu:
        emu.run()
    estimates, _ = run_in_memory(sc, 4, filters=filters, duration=15.0)
    (tmp_path / "estimates.jsonl").write_text("".join(map(estimate_line, estimates)))
    paths = write_report(tmp_path, tmp_path / "report")
    md, page = paths["md"].read_text(), paths["html"].read_text()
    truth = evaluate.load_truth(tmp_path / "emulator" / "truth.csv")
    errors = evaluate.position_errors(truth, evaluate.load_estimates(tmp_path / "estimates.jsonl"),
                                      frame=sc.frame)
    paper = evaluate.PAPER_FIGURES["rssi-centroid"]["figures"]
    assert "## Latitude and longitude (paper 003 Table 1's layout)" in md
    for label, track, key in (("Single SINS", "sins", "geosins"), ("centroid (traditional method)",
                              "centroid", "centroid"), ("weighted centroid (003's method)", "wcl", "wcl")):
        ours = " | ".join(f"{errors[track][m]:.4f}" for m in evaluate.LATLON)
        theirs = " | ".join(f"{paper[key][m]:.4f}" for m in evaluate.LATLON)
        assert f"| {label} | {track} | {ours} |" in md
        assert f"| {label}, paper 003 |  | {theirs} |" in md
        assert f'id="lat-{track}"' in page and f'id="lon-{track}"' in page
    assert 'data-stat="lat_std" data-filter="wcl">' in page
