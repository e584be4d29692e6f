"""The lab orchestrator (``navtwin lab``): the emulated lab with the host on it, and how well
the host did.

Both sides run as the programs users run: ``navtwin emulate`` (real time, recording) through
:func:`navtwin.emulator.api.emulate`, and ``navtwin host`` on its PTYs as its own process, exactly as
it would run on the lab computer's real ports. They share nothing but the ports; the host's
estimates and the emulator's ``truth.csv`` are files, compared when the scenario ends and
shown beside paper 000's figures, as a table and a plot.

Everything lands in one run directory (private, 0700)::

    DIR/emulator/       the emulator's recording: port bytes, truth.csv, scenario.toml
    DIR/host/           the host's recording ('navtwin replay DIR/host' gives the same lines)
    DIR/estimates.jsonl the host's estimate lines
    DIR/innovations.jsonl the fusion tracks' innovations (NIS), 'navtwin host --innovations'
    DIR/host.log        the host's status lines and its final summary
    DIR/report.json     errors per filter, with the paper's figures
    DIR/report.png      tracks and errors over time (with matplotlib)
    DIR/report.html, report.md  the run's report (with matplotlib; lab.report, 'navtwin report')
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from navtwin.emulator.api import EmulatorError, emulate
from navtwin.emulator.control import ControlError
from navtwin.emulator.scenario import ScenarioError, load_scenario
from navtwin.host.replay import config_for
from navtwin.protocols.recording import FAULTS

from . import evaluate
from .live import LiveErrors, Tail
from .audit import AuditError, audit
from .report import ReportError, write_report

HOST_STOP_S = 30.0


class LabError(RuntimeError):
    """The run directory cannot be used, or a side failed: one line."""


def run_dir(path: str | os.PathLike | None) -> Path:
    if path is None:
        return Path(tempfile.mkdtemp(prefix="navtwin-lab-"))  # mode 0700
    d = Path(path).absolute()  # the host is a process of its own: no path may hang on cwd
    if d.exists() and (not d.is_dir() or any(d.iterdir())):
        raise LabError(f"dir: {d}: exists and is not an empty directory; choose a new one")
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    return d


def _log_lines(path: Path) -> list[dict]:
    out = []
    for line in path.read_text(errors="replace").splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            out.append({"text": line})
    return out


def _wait_log(path: Path, pred, timeout: float) -> bool:
    """Poll the host's log until a line satisfies *pred* (True) or *timeout* passes."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(pred(x) for x in _log_lines(path)):
            return True
        time.sleep(0.1)
    return False


#: The lab's phases around its live ticks, and what each means to whoever watches.
PHASES = {
    "starting": "starting the emulator and the host",
    "ended": "the run has ended: the emulator has closed its ports, so the host shows them "
             "down (the end of the run, not a failure)",
    "reporting": "writing the report",
}


class Watch:
    """What the lab shows while it runs. This one, ``navtwin lab``'s, prints a JSON line when
    it starts and every ``tick_s``: the host's last status line and each track's latest error
    against truth (m); ``navtwin demo`` draws the same state in the terminal."""

    tick_s = 2.0

    def __init__(self, out=sys.stderr) -> None:
        self.out = out

    def __enter__(self) -> Watch:
        return self

    def __exit__(self, *exc) -> None:
        """The run is over (a view that holds the terminal gives it back)."""

    def phase(self, name: str) -> None:
        """One of :data:`PHASES` begins (the live ticks run between "running" and "ended")."""
        print(json.dumps({"lab": name}), file=self.out, flush=True)

    def started(self, info: dict) -> None:
        """*info*: ``dir``, ``scenario``, ``seed``, ``duration_s``, ``ports``."""
        print(json.dumps({"lab": "running", **info}), file=self.out, flush=True)

    def tick(self, state: dict) -> None:
        """*state*: ``elapsed_s``; ``emulator``, its control status (virtual time, ports,
        live faults) or None; ``host``, its last status line's body or None; ``tracks``,
        filter -> :class:`navtwin.lab.live.TrackError` (empty until truth and estimates
        meet)."""
        line = {"host": state["host"]} if state["host"] else {}
        if state["tracks"]:
            line["error_m"] = {k: round(v.last, 3) for k, v in state["tracks"].items()}
        if line:
            print(json.dumps(line), file=self.out, flush=True)


def run_lab(scenario: str = "office", *, seed: int | None = None, duration: float | None = None,
            config: str | None = None, filters: str | None = None, directory=None,
            stop: threading.Event | None = None, watch: Watch | None = None,
            plot: bool = True) -> dict:
    """Run the lab; returns the report (errors per filter, paths, both summaries)."""
    stop = stop or threading.Event()
    watch = watch or Watch()
    try:  # refused before anything is made (the emulator would refuse it the same way)
        load_scenario(scenario)
    except ScenarioError as e:
        raise LabError(str(e)) from None
    config = config or config_for(Path(scenario).stem)  # the scenario's lab, as replay finds it
    if config is None:
        raise LabError(f"config: no host config for scenario {scenario!r}; name one (a shipped "
                       "name or a file)")
    d = run_dir(directory)
    log = d / "host.log"
    watch.phase("starting")
    try:
        with emulate(scenario, seed=seed, speed="realtime", duration=duration,
                     link_dir=d / "links", record=d / "emulator") as lab:
            cmd = [sys.executable, "-m", "navtwin", "host", "--xbee", lab.ports["xbee"],
                   "--nanoloc", lab.ports["nanoloc"], "--config", config,
                   "--record", str(d / "host"), "--out", str(d / "estimates.jsonl"),
                   "--innovations", str(d / "innovations.jsonl"),
                   "--status-period", str(min(watch.tick_s, 2.0))]
            if filters is not None:
                cmd += ["--filters", filters]
            with open(log, "wb") as f:
                host = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                        stderr=f)
            watch.started({"dir": str(d), **{k: lab.info[k] for k in (
                "scenario", "seed", "duration_s", "ports")}})
            try:
                _watch(lab, host, log, d, watch, stop)
                if host.poll() is None:  # a host that died is a failure, reported below
                    watch.phase("ended")
                done = lab.stop()
                # the emulator's ports are gone once it has ended: a host that has read all
                # they held reports them down; then it is told to stop
                _wait_log(log, lambda x: x.get("status", {}).get("event") == "port_down", 10.0)
            finally:
                if host.poll() is None:
                    host.send_signal(signal.SIGTERM)
                host.wait(timeout=HOST_STOP_S)
    except EmulatorError as e:
        raise LabError(f"the emulator failed: {str(e).strip().splitlines()[-1]}") from None
    summaries = [x["summary"] for x in _log_lines(log) if "summary" in x]
    if not summaries:
        tail = _log_lines(log)[-1:] or [{"text": "no output"}]
        raise LabError(f"the host failed: {tail[0].get('text', tail[0])}; see {log}")
    watch.phase("reporting")
    return _report(d, summaries[-1], done, plot)


def _watch(lab, host, log: Path, d: Path, watch: Watch, stop: threading.Event) -> None:
    """Until the scenario ends, the host exits or *stop* is set: the live state to *watch*."""
    status_log = Tail(log)
    live = LiveErrors(d / "emulator" / "truth.csv", d / "estimates.jsonl")
    t0, host_t0, emu_t0, last = time.monotonic(), None, None, None
    while lab.running() and host.poll() is None and not stop.is_set():
        stop.wait(watch.tick_s)
        for line in status_log.lines():
            try:
                st = json.loads(line).get("status")
            except json.JSONDecodeError:
                continue
            if isinstance(st, dict):
                host_t0 = st.get("t0_monotonic_ns", host_t0)
                last = st if "t_s" in st else last
        try:
            emu = lab.status()
        except (ControlError, OSError):  # it is ending
            emu = None
        # kept from an earlier status: the tick after the run ended still scores the host,
        # which on a starved machine may have sent its first status line only then
        emu_t0 = (emu or {}).get("t0_monotonic_ns") or emu_t0
        offset = None
        if host_t0 and emu_t0:
            offset = (host_t0 - emu_t0) / 1e9  # scenario = host time + offset
        watch.tick({"elapsed_s": time.monotonic() - t0, "emulator": emu, "host": last,
                    "tracks": live.update(offset)})


def _report(d: Path, host_summary: dict, done: dict, plot: bool) -> dict:
    truth_path = d / "emulator" / "truth.csv"
    report = {"dir": str(d), "host": {k: host_summary.get(k) for k in ("chunks", "lines", "latency")},
              "emulator": done, "errors": {}, "paper_mean_m": evaluate.PAPER_MEAN_ERROR_M}
    if done.get("t0_monotonic_ns") and host_summary.get("t0_monotonic_ns") and truth_path.is_file():
        # scenario time = host time + (host start - emulator start), both on CLOCK_MONOTONIC
        offset = (host_summary["t0_monotonic_ns"] - done["t0_monotonic_ns"]) / 1e9
        truth = evaluate.load_truth(truth_path)
        estimates = evaluate.load_estimates(d / "estimates.jsonl")
        report["time_offset_s"] = offset
        sc = load_scenario(d / "emulator" / "scenario.toml")
        # with the latitude/longitude figures in the scenario's frame (003's Table 1)
        report["errors"] = evaluate.position_errors(truth, estimates, offset, frame=sc.frame)
        if plot:
            try:
                report["plot"] = str(evaluate.plot(truth, estimates, d / "report.png", offset,
                                                   _anchors(sc)))
            except ImportError:
                report["plot"] = None  # matplotlib is in the 'plot' extra
    if (d / "emulator" / FAULTS).is_file() and (d / "emulator" / FAULTS).stat().st_size:
        try:  # faults were injected: did the host lose only what they damaged?
            report["audit"] = audit(d / "emulator", d / "host")
        except AuditError as e:
            report["audit"] = {"ok": False, "error": str(e)}
    (d / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    if plot and report.get("plot") and report["errors"]:  # matplotlib is there: the full report
        try:
            report["html"] = str(write_report(d)["html"])
        except ReportError as e:
            raise LabError(f"the report failed: {e}") from None
    return report


def _anchors(sc) -> dict:
    return {a.id: sc.anchor_position(a)[:2] for a in sc.all_anchors}
