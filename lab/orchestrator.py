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

With several vehicles (``vehicles=N``: emulator.fleet's convoy; ``network`` how they share the
air), the scenario as run is DIR/scenario.toml, and the hosts that follow them (lab.fleet) are
one on the shared ports, or one per vehicle on its own ports: host ``k`` > 1 has
DIR/host<k>/, host<k>.toml (its config), host<k>.log, estimates<k>.jsonl and
innovations<k>.jsonl (host 1's config is DIR/host.toml). report.json then also has
``vehicles``: per vehicle its truth file, its host's estimates file and vehicle number there,
and its errors per filter; ``errors`` stays the first followed car's (``car``, when not 1;
``follow`` picks the cars to follow, default all).
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
from navtwin.emulator.fleet import convoy
from navtwin.emulator.scenario import Scenario, ScenarioError, load_scenario
from navtwin.emulator.truth import file_name as truth_file
from navtwin.host import config as host_config
from navtwin.host.replay import config_for
from navtwin.protocols.recording import FAULTS

from . import evaluate
from .fleet import FleetError, Follower, followers
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
        meet); with several vehicles ``vehicles``, vehicle -> its ``tracks`` (1 included)."""
        line = {"host": state["host"]} if state["host"] else {}
        if state["tracks"]:
            line["error_m"] = {k: round(v.last, 3) for k, v in state["tracks"].items()}
        if line:
            print(json.dumps(line), file=self.out, flush=True)


def _files(k: int) -> dict[str, str]:
    """Host *k*'s files in the run directory (module doc)."""
    sfx = "" if k == 1 else str(k)
    return {"record": f"host{sfx}", "config": f"host{sfx}.toml", "log": f"host{sfx}.log",
            "estimates": f"estimates{sfx}.jsonl", "innovations": f"innovations{sfx}.jsonl"}


def run_lab(scenario: str = "office", *, seed: int | None = None, duration: float | None = None,
            config: str | None = None, filters: str | None = None, directory=None,
            stop: threading.Event | None = None, watch: Watch | None = None,
            plot: bool = True, vehicles: int | None = None, network: str | None = None,
            follow: tuple[int, ...] | None = None) -> dict:
    """Run the lab; returns the report (errors per filter, paths, both summaries). With
    *vehicles* N, a convoy of N cars sharing the air as *network* says (module doc);
    *follow*: the cars the hosts follow (default all)."""
    stop = stop or threading.Event()
    watch = watch or Watch()
    sc, config, hosts = fleet_lab(scenario, vehicles, network, config, follow)
    d = run_dir(directory)
    scenario, config = write_fleet(d, sc, hosts, scenario, config)
    watch.phase("starting")
    try:
        with emulate(scenario, seed=seed, speed="realtime", duration=duration,
                     link_dir=d / "links", record=d / "emulator") as lab:
            procs = [start_host(d, h, lab, config, filters, min(watch.tick_s, 2.0))
                     for h in hosts]
            watch.started({"dir": str(d), **{k: lab.info[k] for k in (
                "scenario", "seed", "duration_s", "ports")}, "vehicles": len(sc.fleet)})
            try:
                _watch(lab, procs, hosts, d, watch, stop)
                if all(p.poll() is None for p in procs):  # a host that died: reported below
                    watch.phase("ended")
                done = lab.stop()
                # the emulator's ports are gone once it has ended: a host that has read all
                # they held reports them down; then it is told to stop
                hosts_read([d / _files(h.number)["log"] for h in hosts], 10.0)
            finally:
                stop_hosts(procs)
    except EmulatorError as e:
        raise LabError(f"the emulator failed: {str(e).strip().splitlines()[-1]}") from None
    summaries = []
    for h in hosts:
        log = d / _files(h.number)["log"]
        mine = [x["summary"] for x in _log_lines(log) if "summary" in x]
        if not mine:
            tail = _log_lines(log)[-1:] or [{"text": "no output"}]
            raise LabError(f"the host failed: {tail[0].get('text', tail[0])}; see {log}")
        summaries.append(mine[-1])
    watch.phase("reporting")
    return _report(d, summaries, hosts, done, plot)


def fleet_lab(scenario: str, vehicles: int | None, network: str | None, config: str | None,
              follow: tuple[int, ...] | None) -> tuple[Scenario, str, list[Follower]]:
    """The lab *scenario* makes (with *vehicles* N, emulator.fleet's convoy sharing the air
    as *network* says), the host config (*config*, else the scenario's, as replay finds it)
    and the hosts that follow the cars *follow* (default all; lab.fleet); LabError (one
    line) if any of them cannot be, refused before anything is made."""
    try:
        sc = load_scenario(scenario)
        if vehicles is not None:
            sc = convoy(sc, vehicles, network=network)
    except ScenarioError as e:
        raise LabError(str(e)) from None
    config = config or config_for(Path(scenario).stem)
    if config is None:
        raise LabError(f"config: no host config for scenario {scenario!r}; name one (a shipped "
                       "name or a file)")
    try:
        return sc, config, followers(sc, host_config.load(config), follow)
    except (FleetError, host_config.ConfigError) as e:
        raise LabError(str(e)) from None


def write_fleet(d: Path, sc: Scenario, hosts: list[Follower], scenario: str,
                config: str) -> tuple[str | Path, str | None]:
    """What the emulator runs and host 1's config, for :func:`start_host`: *scenario* and
    *config* as given for one vehicle; with several, the fleet as written to
    DIR/scenario.toml, and None: each host reads the config written for it (module doc)."""
    if len(sc.fleet) == 1:
        return scenario, config
    (d / "scenario.toml").write_text(sc.to_toml(), encoding="utf-8")
    for h in hosts:
        (d / _files(h.number)["config"]).write_text(h.config.to_toml(), encoding="utf-8")
    return d / "scenario.toml", None


def start_host(d: Path, h: Follower, lab, config: str | None, filters: str | None,
               status_period: float) -> subprocess.Popen:
    """``navtwin host`` for follower *h* on its ports of the running *lab*, as a user runs it,
    its files in *d* (:func:`_files`; *config*: the config's name for a one-vehicle lab;
    None: the file :func:`write_fleet` wrote)."""
    f = _files(h.number)
    cmd = [sys.executable, "-m", "navtwin", "host"]
    for given, port in h.inputs.items():
        cmd += [f"--{given}", lab.ports[port]]
    cmd += ["--config", config or str(d / f["config"]), "--record", str(d / f["record"]),
            "--out", str(d / f["estimates"]), "--innovations", str(d / f["innovations"]),
            "--status-period", str(status_period)]
    if filters is not None:
        cmd += ["--filters", filters]
    with open(d / f["log"], "wb") as log:
        return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log)


def hosts_read(logs: list[Path], timeout: float) -> None:
    """Once the emulator has ended and its ports are gone: wait (each up to *timeout*) until
    every host's log says it read what they held (its ports down)."""
    for log in logs:
        _wait_log(log, lambda x: x.get("status", {}).get("event") == "port_down", timeout)


def stop_hosts(procs: list[subprocess.Popen]) -> None:
    """SIGTERM to every host still running, then wait for each (HOST_STOP_S)."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        p.wait(timeout=HOST_STOP_S)


def _followed(d: Path, hosts: list[Follower]) -> dict[int, dict]:
    """Per vehicle of the lab: its truth file, its host's estimates file, its number there."""
    return {v: {"truth": f"emulator/{truth_file(v)}", "estimates": _files(h.number)["estimates"],
                "host": h.number, "host_vehicle": k}
            for h in hosts for k, v in enumerate(h.vehicles, 1)}


def _watch(lab, procs, hosts: list[Follower], d: Path, watch: Watch, stop: threading.Event) -> None:
    """Until the scenario ends, a host exits or *stop* is set: the live state to *watch*
    (``host``: host 1's last status line)."""
    logs = {h.number: Tail(d / _files(h.number)["log"]) for h in hosts}
    followed = _followed(d, hosts)
    lives = {v: LiveErrors(d / f["truth"], d / f["estimates"], f["host_vehicle"])
             for v, f in followed.items()}
    t0, emu_t0, last = time.monotonic(), None, None
    host_t0: dict[int, int] = {}
    while lab.running() and all(p.poll() is None for p in procs) and not stop.is_set():
        stop.wait(watch.tick_s)
        for k, log in logs.items():
            for line in log.lines():
                try:
                    st = json.loads(line).get("status")
                except json.JSONDecodeError:
                    continue
                if isinstance(st, dict):
                    if st.get("t0_monotonic_ns"):
                        host_t0[k] = st["t0_monotonic_ns"]
                    last = st if "t_s" in st and k == 1 else last
        try:
            emu = lab.status()
        except (ControlError, OSError):  # it is ending
            emu = None
        # kept from an earlier status: the tick after the run ended still scores the host,
        # which on a starved machine may have sent its first status line only then
        emu_t0 = (emu or {}).get("t0_monotonic_ns") or emu_t0
        tracks = {}
        for v, live in lives.items():
            mine = host_t0.get(followed[v]["host"])
            # scenario time = host time + offset, each host on its own start
            tracks[v] = live.update((mine - emu_t0) / 1e9 if mine and emu_t0 else None)
        state = {"elapsed_s": time.monotonic() - t0, "emulator": emu, "host": last,
                 "tracks": tracks[hosts[0].vehicles[0]]}
        if len(lives) > 1:
            state["vehicles"] = tracks
        watch.tick(state)


def _report(d: Path, summaries: list[dict], hosts: list[Follower], done: dict, plot: bool) -> dict:
    car = hosts[0].vehicles[0]  # the first car followed: host 1's vehicle 1
    truth_path = d / "emulator" / truth_file(car)
    host_summary = summaries[0]
    report = {"dir": str(d), "host": {k: host_summary.get(k) for k in ("chunks", "lines", "latency")},
              "emulator": done, "errors": {}, "paper_mean_m": evaluate.PAPER_MEAN_ERROR_M}
    if car != 1:
        report["car"] = car
    if done.get("t0_monotonic_ns") and host_summary.get("t0_monotonic_ns") and truth_path.is_file():
        # scenario time = host time + (host start - emulator start), both on CLOCK_MONOTONIC
        offset = (host_summary["t0_monotonic_ns"] - done["t0_monotonic_ns"]) / 1e9
        truth = evaluate.load_truth(truth_path)
        estimates = evaluate.load_estimates(d / "estimates.jsonl")
        report["time_offset_s"] = offset
        sc = load_scenario(d / "emulator" / "scenario.toml")
        # with the latitude/longitude figures in the scenario's frame (003's Table 1)
        report["errors"] = evaluate.position_errors(truth, estimates, offset, frame=sc.frame)
        if len(sc.fleet) > 1:  # every vehicle against its own truth, each host on its clock
            report["vehicles"] = {}
            for v, f in _followed(d, hosts).items():
                host_offset = (summaries[f["host"] - 1]["t0_monotonic_ns"] - done["t0_monotonic_ns"]) / 1e9
                mine = evaluate.load_estimates(d / f["estimates"], vehicle=f["host_vehicle"])
                report["vehicles"][str(v)] = {**f, "time_offset_s": host_offset, "errors": evaluate.position_errors(
                    evaluate.load_truth(d / f["truth"]), mine, host_offset, frame=sc.frame)}
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
