"""``navtwin lab``: the emulated lab with the host on it, and how well the host did.

The emulator runs as its own process (``navtwin emulate``, real time, recording), exactly as a
user would start it; the host service reads its PTYs in this process, as it would read real
ports. Neither imports the other: the ports and the emulator's files are all they share.
When the scenario ends, the host's estimates are compared with the emulator's ``truth.csv``
and shown beside paper 000's figures, as a table and a plot.

Everything lands in one run directory (private, 0700)::

    DIR/emulator/       the emulator's recording: port bytes, truth.csv, scenario.toml
    DIR/host/           the host's recording ('navtwin replay DIR/host' gives the same lines)
    DIR/estimates.jsonl the host's estimate lines
    DIR/report.json     errors per filter, with the paper's figures
    DIR/report.png      tracks and errors over time (with matplotlib)
"""
from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from . import config as host_config
from . import evaluate

READY_TIMEOUT_S = 60.0


class LabError(RuntimeError):
    """The emulator did not start or the run directory cannot be used: one line."""


def default_config(scenario: str) -> str:
    """The shipped host config of a scenario's lab: ``office``; ``corridor`` for both corridor
    scenarios (same survey)."""
    for name in (Path(scenario).stem, Path(scenario).stem.split("-")[0]):
        if name in host_config.shipped():
            return name
    raise LabError(f"no host config for scenario {scenario!r}; give --config NAME|FILE "
                   f"(shipped: {', '.join(host_config.shipped())})")


def run_dir(path: str | os.PathLike | None) -> Path:
    if path is None:
        return Path(tempfile.mkdtemp(prefix="navtwin-lab-"))  # mode 0700
    d = Path(path)
    if d.exists() and (not d.is_dir() or any(d.iterdir())):
        raise LabError(f"--dir {d}: exists and is not an empty directory; choose a new one")
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    return d


class EmulatorProcess:
    """``navtwin emulate`` as a child process, read line by line (its JSON protocol)."""

    def __init__(self, cmd: list[str], log: Path) -> None:
        self.log = log
        with open(log, "wb") as f:
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=f)
        self._buf = b""

    def next_message(self, deadline: float, stop: threading.Event) -> dict | None:
        """The next JSON line, or None at *deadline*, on *stop* or when the emulator ended."""
        fd = self.proc.stdout.fileno()
        while b"\n" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0 or stop.is_set():
                return None
            if select.select([fd], [], [], min(left, 0.2))[0]:
                chunk = os.read(fd, 4096)
                if not chunk:
                    return None
                self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return json.loads(line)

    def error(self) -> str:
        """The emulator's last stderr line (its one-line error, if it failed)."""
        lines = self.log.read_text(errors="replace").strip().splitlines()
        return lines[-1] if lines else f"no output; see {self.log}"

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(timeout=30)
        self.proc.stdout.close()


def run_lab(scenario: str = "office", *, seed: int | None = None, duration: float | None = None,
            config: str | None = None, filters=None, directory=None,
            stop: threading.Event | None = None, status=sys.stderr, plot: bool = True) -> dict:
    """Run the lab; returns the report (errors per filter, paths, summaries)."""
    from .service import Service

    stop = stop or threading.Event()
    cfg = host_config.load(config or default_config(scenario))
    filters = tuple(filters or cfg.filters)
    d = run_dir(directory)
    cmd = [sys.executable, "-m", "protocols", "emulate", "--scenario", scenario,
           "--speed", "realtime", "--record", str(d / "emulator"), "--link-dir", str(d / "links")]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    if duration is not None:
        cmd += ["--duration", str(duration)]
    emu = EmulatorProcess(cmd, d / "emulator.log")
    try:
        ready = emu.next_message(time.monotonic() + READY_TIMEOUT_S, stop)
        if not ready or not ready.get("ready"):
            raise LabError(f"the emulator did not start: {emu.error()}")
        ports = {p: ready["ports"][p] for p in ("xbee", "nanoloc")}
        print(json.dumps({"lab": "running", "dir": str(d), "scenario": ready["scenario"],
                          "seed": ready["seed"], "duration_s": ready["duration_s"],
                          "ports": ports}), file=status, flush=True)
        with open(d / "estimates.jsonl", "w") as out:
            service = Service(ports, cfg, filters, out=out, record=d / "host", status=status)
            host_stop = threading.Event()
            host = threading.Thread(target=service.run, args=(host_stop,), name="host")
            host.start()
            done = None
            while done is None and not stop.is_set():
                msg = emu.next_message(time.monotonic() + 1.0, stop)
                if msg is None and emu.proc.poll() is not None:
                    break
                if msg and msg.get("done"):
                    done = msg
            _settle(service)
            host_stop.set()
            host.join()
    finally:
        emu.close()
    return _report(d, cfg, service.summary(), done, plot)


def _settle(service, quiet_s: float = 0.3, limit_s: float = 5.0) -> None:
    """Let the host take the last bytes the emulator wrote: until nothing new arrives for
    *quiet_s* (at most *limit_s*). The emulator's "done" line comes after its last write, so
    what is still in flight is only in the PTY buffers and the host's reader threads."""
    end = time.monotonic() + limit_s
    last, since = service.chunks, time.monotonic()
    while time.monotonic() < end and time.monotonic() - since < quiet_s:
        time.sleep(0.05)
        if service.chunks != last:
            last, since = service.chunks, time.monotonic()


def _report(d: Path, cfg, host_summary: dict, done: dict | None, plot: bool) -> dict:
    truth_path = d / "emulator" / "truth.csv"
    report = {"dir": str(d), "host": {k: host_summary.get(k) for k in ("chunks", "lines", "latency")},
              "emulator": done, "errors": {}, "paper_mean_m": evaluate.PAPER_MEAN_ERROR_M}
    if done and done.get("t0_monotonic_ns") and truth_path.is_file():
        # scenario time = host time + (host start - emulator start), both on CLOCK_MONOTONIC
        offset = (host_summary["t0_monotonic_ns"] - done["t0_monotonic_ns"]) / 1e9
        truth = evaluate.load_truth(truth_path)
        estimates = evaluate.load_estimates(d / "estimates.jsonl")
        report["time_offset_s"] = offset
        report["errors"] = evaluate.position_errors(truth, estimates, offset)
        if plot:
            try:
                report["plot"] = str(evaluate.plot(truth, estimates, d / "report.png", offset,
                                                   cfg.anchors))
            except ImportError:
                report["plot"] = None  # matplotlib is in the 'plot' extra
    (d / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


# -- CLI ----------------------------------------------------------------------------------

def register(sub) -> None:
    p = sub.add_parser(
        "lab", help="run the emulated lab with the host on it, and report its accuracy",
        description="Start 'navtwin emulate' (real time, recording) as its own process, run the "
        "host service on its PTYs, and when the scenario ends compare the host's estimates with "
        "the emulator's truth.csv: mean and max position error per filter beside paper 000's "
        "figures, and a plot. Ctrl-C ends the run early and still reports.")
    p.add_argument("--scenario", default="office", metavar="NAME|FILE",
                   help="a shipped scenario (office, corridor, corridor-outage) or a TOML file")
    p.add_argument("--seed", type=int, help="emulator seed (default: the scenario's)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="seconds of the scenario to run (default: all of it)")
    p.add_argument("--config", metavar="NAME|FILE",
                   help="host config (default: the scenario's lab, e.g. office)")
    p.add_argument("--filters", metavar="LIST", help="comma list or all (default: the config's)")
    p.add_argument("--dir", metavar="DIR", help="run directory (default: a new private temp dir)")
    p.add_argument("--no-plot", dest="plot", action="store_false", help="skip report.png")
    p.set_defaults(func=run)


def run(args) -> int:
    from protocols.cli import UsageError, stop_on_signals

    if args.duration is not None and args.duration <= 0:
        raise UsageError(f"--duration {args.duration}: must be positive")
    stop = threading.Event()
    try:
        filters = host_config.parse_filters(args.filters) if args.filters else None
        with stop_on_signals(stop):
            report = run_lab(args.scenario, seed=args.seed, duration=args.duration,
                             config=args.config, filters=filters, directory=args.dir, stop=stop,
                             plot=args.plot)
    except (LabError, host_config.ConfigError) as e:
        raise UsageError(str(e)) from None
    print(evaluate.table(report["errors"]) if report["errors"] else "no estimates to compare")
    print(f"\nrun directory: {report['dir']}" + (f"\nplot: {report['plot']}" if report.get("plot")
                                                  else ""))
    return 0
