"""`navtwin lab`: the emulator and the host, two processes on PTYs, judged against truth.csv."""
import json

import pytest

from navtwin.lab.report import fmt

from ..helpers import navtwin

pytestmark = [pytest.mark.pty, pytest.mark.slow]


def test_lab_runs_and_reports_against_truth(tmp_path):
    d = tmp_path / "run"
    # a relative --dir, as users type it: the host (a process of its own) must find the links
    p = navtwin("lab", "--duration", "16", "--dir", "run", "--no-plot", timeout=180, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    report = json.loads((d / "report.json").read_text())
    errors = report["errors"]
    assert set(errors) == {"sins", "wsn", "kf", "ekf", "ukf"}
    assert all(e["n"] >= 100 for e in errors.values())  # ~10 estimates/s for 16 s each
    # the fused tracks beat pure WSN on the same run (pure SINS only drifts after alignment)
    for name in ("kf", "ekf", "ukf"):
        assert errors[name]["mean"] < errors["wsn"]["mean"]
    assert errors["wsn"]["mean"] < 1.5  # bounded: the emulated office is calibrated near 000's 0.64 m
    assert abs(report["time_offset_s"]) < 5  # both clocks are this machine's CLOCK_MONOTONIC
    # the host's own recording replays to its live lines
    replayed = navtwin("replay", d / "host")
    assert replayed.stdout == (d / "estimates.jsonl").read_text()
    assert "filter" in p.stdout and str(d) in p.stdout
    # while it ran: JSON lines with the host's status and every track's latest error
    live = [json.loads(x) for x in p.stderr.splitlines() if x.startswith("{")]
    assert any(set(x.get("error_m", {})) == set(errors) for x in live)
    assert any("host" in x for x in live)
    assert [x["lab"] for x in live if "lab" in x] == ["starting", "running", "ended", "reporting"]
    # the host wrote its innovations; --no-plot made no report, navtwin report makes it from
    # the live run's files, with the run's host-time offset: the numbers of report.json
    inn = [json.loads(x) for x in (d / "innovations.jsonl").read_text().splitlines()]
    assert {r["filter"] for r in inn} == {"kf", "ekf", "ukf"}
    assert not (d / "report.html").exists()
    made = navtwin("report", d)
    assert made.returncode == 0, made.stderr[-2000:]
    md = (d / "report.md").read_text()
    for name, e in errors.items():
        assert fmt(e["mean"]) in md and fmt(e["max"]) in md, name
    assert f"| host time offset (s) | {report['time_offset_s']:.6f} |" in md


def test_lab_reports_a_bad_scenario_in_one_line(tmp_path):
    p = navtwin("lab", "--scenario", "nowhere", "--config", "office", "--dir", tmp_path / "r")
    err = p.stderr.strip()
    assert p.returncode == 2 and len(err.splitlines()) == 1 and "nowhere" in err


@pytest.mark.parametrize("network, follow", [("shared", "1,2"), ("per-vehicle", "2,1")])
def test_a_lab_of_two_cars_scores_each_against_its_own_truth(tmp_path, network, follow):
    """Two cars, one host following both on the shared air or one host each on its own
    ports: every car's fused tracks stay near its own truth, the main figures are the first
    followed car's, and `navtwin report` shows both."""
    d = tmp_path / "run"
    p = navtwin("lab", "--vehicles", "2", "--network", network, "--follow", follow, "--duration",
                "14", "--dir", d, "--filters", "wsn,kf", "--no-plot", timeout=180)
    assert p.returncode == 0, p.stderr[-2000:]
    report = json.loads((d / "report.json").read_text())
    cars, first = report["vehicles"], follow.split(",")[0]
    assert set(cars) == {"1", "2"} and report["errors"] == cars[first]["errors"]
    assert report.get("car", 1) == int(first)
    hosts = {c["host"] for c in cars.values()}
    assert hosts == ({1} if network == "shared" else {1, 2})
    for car in cars.values():
        assert car["errors"]["kf"]["n"] >= 50 and car["errors"]["kf"]["mean"] < 1.0, car
    assert "mean position error per vehicle and track" in p.stdout
    live = [json.loads(x) for x in p.stderr.splitlines() if x.startswith("{")]
    assert any(x.get("lab") == "running" and x.get("vehicles") == 2 for x in live)
    made = navtwin("report", d)
    assert made.returncode == 0, made.stderr[-2000:]
    md = (d / "report.md").read_text()
    assert "## Cars" in md and fmt(cars["2"]["errors"]["kf"]["mean"]) in md


def test_network_without_vehicles_is_one_line(tmp_path):
    p = navtwin("lab", "--network", "per-vehicle", "--dir", tmp_path / "r")
    assert p.returncode == 2 and "pass --vehicles N" in p.stderr and len(p.stderr.strip().splitlines()) == 1
