"""``navtwin report``: rendered from a short run written as a run directory (the emulator's
recording at max speed, the in-memory host's estimates and innovations of the same run):
every filter's plot and table row, the numbers recomputed from estimates.jsonl, no external
reference, and a headless Chromium screenshot that is not blank."""
import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario, with_faults
from navtwin.host.output import estimate_line, innovation_line
from navtwin.lab import evaluate
from navtwin.lab.report import ROWS, cell, fmt, write_report
from navtwin.lab.run import run_in_memory

from ..helpers import navtwin

pytest.importorskip("matplotlib")

DURATION_S = 12.0
FAULT = "anchor_outage:anchor=2,start_s=9,end_s=10"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    sc = with_faults(load_scenario("office"), [FAULT])
    with Emulation(sc, 3, speed=None, duration_s=DURATION_S, ports=False,
                   record=d / "emulator") as emu:
        emu.run()
    innovations = []
    estimates, _ = run_in_memory(sc, 3, duration=DURATION_S,
                                 on_innovation=lambda *f: innovations.append(innovation_line(*f)))
    (d / "estimates.jsonl").write_text("".join(map(estimate_line, estimates)))
    (d / "innovations.jsonl").write_text("".join(innovations))
    (d / "host.log").write_text(json.dumps({"summary": HOST_SUMMARY}) + "\n")
    return d


#: The host's summary line, as navtwin host ends its log (the parts the report shows).
HOST_SUMMARY = {"counts": {"imu": 1200, "reports": 480}, "link_dbm": -40, "max_late_ms": 1.5,
                "reconnects": {"xbee": 1, "nanoloc": 0},
                "latency": {"n": 540, "p50_ms": 0.75, "p99_ms": 3.204, "max_ms": 12.5}}


@pytest.fixture(scope="module")
def report(run_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    paths = write_report(run_dir, out)
    return {k: p.read_text() for k, p in paths.items()} | {"paths": paths}


def _recomputed(run_dir):
    truth = evaluate.load_truth(run_dir / "emulator" / "truth.csv")
    est = evaluate.load_estimates(run_dir / "estimates.jsonl")
    return est, evaluate.position_errors(truth, est)  # in-memory: host time is scenario time


def test_every_filter_has_its_plots_and_table_cells_equal_to_the_estimates_file(run_dir, report):
    page = report["html"]
    est, errors = _recomputed(run_dir)
    assert sorted(est) == ["ekf", "kf", "sins", "ukf", "wsn"]
    for name in est:
        for fig in ("track", "error"):
            assert f'id="{fig}-{name}"' in page, (fig, name)
    for name in ("kf", "ekf", "ukf"):  # the fusion tracks: NEES against the band, and NIS
        assert f'id="nees-{name}"' in page
        assert re.search(rf'id="nis-{name}-(fix|tdoa)', page)
    assert 'id="pcrb"' in page
    cells = dict(((m[1], m[2]), m[3]) for m in re.finditer(
        r'<td data-stat="([^"]+)" data-filter="([^"]+)">([^<]*)</td>', page))
    for name, e in errors.items():
        for key, _ in ROWS:
            assert cells[(key, name)] == cell(e, key), (key, name)
    # the paper's figures beside ours (000, office)
    assert cells[("paper:mean", "ukf")] == fmt(evaluate.PAPER_MEAN_ERROR_M["ukf"])


def test_markdown_rows_equal_the_estimates_file(run_dir, report):
    _, errors = _recomputed(run_dir)
    lines = report["md"].splitlines()
    head = next(x for x in lines if x.startswith("| statistic |"))
    names = [c.strip() for c in head.strip("|").split("|")][1:]
    assert names == list(errors)
    rows = {}
    for x in lines[lines.index(head) + 2:]:
        if not x.startswith("|"):
            break
        label, *values = [c.strip() for c in x.strip("|").split("|")]
        rows[label] = values
    for key, label in ROWS:
        assert rows[label] == [cell(errors[n], key) for n in names], label


def test_faults_innovations_and_provenance(run_dir, report):
    md = report["md"]
    ledger = [json.loads(x) for x in (run_dir / "emulator" / "faults.jsonl").read_text().splitlines()]
    assert ledger and {f["kind"] for f in ledger} == {"anchor_outage"}
    assert f"| anchor_outage | {len(ledger)} |" in md
    nis = [json.loads(x) for x in (run_dir / "innovations.jsonl").read_text().splitlines()]
    # TDOA of four anchors has 3 dimensions, of three (anchor 2 out) 2: one row each
    for dim in (2, 3):
        q = np.array([r["nis"] for r in nis if r["filter"] == "ekf" and r["kind"] == "tdoa"
                      and r["dim"] == dim])
        assert f"| ekf | tdoa/{dim} | {dim} | {len(q)} | {fmt(float(q.mean()))} |" in md
    import hashlib

    digest = hashlib.sha256((run_dir / "estimates.jsonl").read_bytes()).hexdigest()
    assert f"| sha256 estimates.jsonl | {digest} |" in md
    assert "| seed | 3 |" in md


def test_html_is_self_contained(report):
    page = report["html"]
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, re.I)
    assert "<script" not in page.lower() and "<link" not in page.lower()
    assert "@import" not in page and not re.search(r"url\((?!#)", page)  # only the SVG's own ids
    assert page.count("<svg") == 4  # tracks, error, NEES, NIS


def _chromium():
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None and os.environ.get("NAVTWIN_CHROMIUM") == "required":
        pytest.fail("chromium is not installed; .ci/run requires it (apt-get install chromium)")
    return path


@pytest.mark.slow
def test_headless_chromium_screenshot_is_not_blank(report, tmp_path):
    chromium = _chromium()
    if chromium is None:
        pytest.skip("chromium is not installed (scripts/test installs it when root)")
    shot = tmp_path / "report.png"
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--screenshot={shot}", "--window-size=1280,2000",
                    report["paths"]["html"].as_uri()], capture_output=True, timeout=120,
                   check=True, stdin=subprocess.DEVNULL, env={**os.environ, "HOME": str(tmp_path)})
    from matplotlib.image import imread

    img = imread(shot)[..., :3]
    assert img.shape[:2] == (2000, 1280)
    # a page of plots and tables: far from uniform, and in more than a few colours
    assert img.std() > 0.1
    colours = np.unique((img.reshape(-1, 3) * 255).round().astype(np.uint8), axis=0)
    assert len(colours) > 50
    # the plots' own colours (matplotlib's C0 blue, C1 orange) are on the page
    for rgb in ((31, 119, 180), (255, 127, 14)):
        assert (np.abs(colours.astype(int) - rgb).max(axis=1) <= 8).any(), rgb


def test_cli_bad_run_dir_is_one_line_and_exit_2(tmp_path):
    p = navtwin("report", tmp_path)
    assert p.returncode == 2
    assert p.stdout == "" and len(p.stderr.strip().splitlines()) == 1
    assert "emulator/truth.csv" in p.stderr


@pytest.mark.parametrize("text, words", [("[]", "a JSON list"), ("{", "unreadable JSON"),
                                         ('{"time_offset_s": "1"}', "time_offset_s must be a number (got '1')"),
                                         ('{"audit": [1]}', "audit")])
def test_a_report_json_that_is_no_lab_report_is_one_line_and_exit_2(run_dir, tmp_path, capsys,
                                                                    text, words):
    from navtwin.cli.main import main

    d = tmp_path / "run"
    shutil.copytree(run_dir, d)
    (d / "report.json").write_text(text)
    before = sorted(p.name for p in d.rglob("*"))
    assert main(["report", str(d)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert captured.out == "" and len(lines) == 1, captured.err
    assert f"{d}/report.json" in lines[0] and words in lines[0] and "re-run" in lines[0]
    assert sorted(p.name for p in d.rglob("*")) == before  # no report written over it


def test_the_report_reads_as_figures_for_a_newcomer(run_dir, report):
    md, page = report["md"], report["html"]
    # latency as figures, not a JSON cell
    assert "| host latency (ms) | p50 0.750, p99 3.204, max 12.500 (n 540) |" in md
    assert '{"n"' not in md and "reconnects | xbee 1, nanoloc 0 |" in md
    # the at-rest updates (NIS ~1e-8) are not rows of 0.0000: a note names them
    nis = [json.loads(x) for x in (run_dir / "innovations.jsonl").read_text().splitlines()]
    still = [r for r in nis if r["kind"] == "stationary"]
    assert still and max(r["nis"] for r in still) < 1e-3
    assert "| stationary |" not in md and "| 0.0000 |" not in md
    assert f"Left out: stationary ({len(still)} updates)" in md and "Left out: stationary" in page
    # one small error panel per track (each its own axes), on one scale
    error_svg = page[page.index("id=fig-error>"):page.index("</svg>", page.index("id=fig-error>"))]
    assert len(re.findall(r'<g id="axes_\d+"', error_svg)) == 5
    # 12 s of office beside paper 000's whole loop: said so
    note = re.search(r"<p class=note id=paper-note>([^<]*)</p>", page)[1]
    assert "one loop of the taped line, 70 s" in note and "covers 12.0 s" in note, note
    assert "too short to set beside those figures" in md
