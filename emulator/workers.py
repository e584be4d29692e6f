"""One emulation's vehicles spread over worker processes, on one schedule.

One process keeps the schedule of as many vehicles as one core (and one GIL) can generate
and write; beyond that, :class:`Workers` runs the vehicles in K processes. Only vehicles that
share nothing can be split: with a coordinator and a nanoLOC network per vehicle
(``network = "per-vehicle"``) every vehicle draws from streams of its own (emulator.rng),
so a worker that builds only its vehicles (``Emulation(vehicles=...)``) gives each of them,
under its own port names, the bytes the single-process run gives it.

Vehicle n goes to worker (n - 1) mod K. Each worker (``python -m navtwin.emulator.workers``)
reads one JSON line on stdin: the scenario as run (``Scenario.to_toml``), seed, speed,
duration, timing mode, its vehicles and a private link directory; it prints its ``ready``
line, waits for ``{"t0_monotonic_ns": T}`` (every worker the same T, so all vehicles run on
one clock) and prints its ``done`` line; an error is one JSON line ``{"error": ...}``.
SIGINT and SIGTERM stop it as they stop ``navtwin emulate``, and so does its parent's death
(``PR_SET_PDEATHSIG``: a parent killed outright leaves no worker writing). The parent holds the user's
link directory (its lock, one stable link per port, to the workers' PTYs), prints one ready
line listing every port and one done line with the workers' per-port entries merged; a
worker that ends without its done line stops the others and ends the run with one line.

What needs the one loop stays out: the control socket and the tap (``control`` and ``tap``
are null in the ready line), and recording (refused: each worker would write its own).

``--workers auto`` (:func:`auto`): the cost of one vehicle, measured at start-up by making
vehicle 1's first second at full speed, times LOOP_FACTOR (its writes and the loop cost
about as much again as making it: office at --speed max and at realtime, docs/performance.md),
times the speed, against BUDGET of a core per worker, at most ``os.cpu_count()``.
"""
from __future__ import annotations

import json
import math
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time

from navtwin.common.signals import stopper

from .pty import LinkDir
from .runner import SEC, RunError, speed_name
from .timing import die_with_parent

LOOP_FACTOR = 2.5  # a paced vehicle's CPU over the CPU of making its events (N=50: 8.8 / 3.8)
BUDGET = 0.5  # of a core per worker: the rest is headroom for keeping the schedule
START_NS = SEC // 5  # from the ready line to scenario time 0 (each worker made its first
#                      second before its ready line)


def refusal(scenario, workers: int) -> str | None:
    """Why *scenario* cannot be split over *workers* processes (None: it can)."""
    n = len(scenario.fleet)
    if workers > 1 and n > 1 and not (scenario.units("coordinator") == scenario.units("gateway") == n):
        return ("workers: vehicles that share a coordinator or an anchors' network cannot be "
                "split over processes; pass --network per-vehicle, or --workers 1")
    return None


def vehicle_cost(scenario, seed: int) -> float:
    """CPU seconds one vehicle costs per second of scenario time (measured: vehicle 1's
    first second made at full speed, times LOOP_FACTOR)."""
    from .world import World

    world = World(scenario, seed, vehicles=(1,))
    t = time.process_time()
    world.advance(min(SEC, world.duration_ns))
    return (time.process_time() - t) * SEC / min(SEC, world.duration_ns) * LOOP_FACTOR


def auto(scenario, seed: int, speed: float | None) -> int:
    """Workers for *scenario* at *speed*: enough that each carries BUDGET of a core, at most
    os.cpu_count() and the vehicles; one at --speed max or when they cannot be split."""
    n = len(scenario.fleet)
    if speed is None or refusal(scenario, 2) is not None or n == 1:
        return 1
    need = n * vehicle_cost(scenario, seed) * speed / BUDGET
    return max(1, min(math.ceil(need), os.cpu_count() or 1, n))


class Workers:
    """*scenario*'s vehicles on *workers* processes: :meth:`info` (the ready line),
    :meth:`run` (the done line), :meth:`close`. Arguments as for ``Emulation``."""

    def __init__(self, scenario, seed: int | None, workers: int, *, speed: float | None,
                 duration_s: float | None, link_dir=None, timing: str = "auto",
                 progress: bool = False, chosen: str | None = None) -> None:
        if (problem := refusal(scenario, workers)) is not None:
            raise RunError(problem)
        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        self.speed = speed
        self.chosen = chosen  # how the count was chosen ("auto: ..."), for the ready line
        n = len(scenario.fleet)
        k = min(workers, n)
        self.vehicles = [list(range(i, n + 1, k)) for i in range(1, k + 1)]
        self.order = [name for name, _ in scenario.instances()]  # as Emulation lists them
        self.link_dir = LinkDir(link_dir, self.order)
        self._private = tempfile.mkdtemp(prefix="navtwin-workers-")
        self._lines: queue.Queue = queue.Queue()  # (worker, parsed line or None at its end)
        self.procs: list[subprocess.Popen] = []
        self.ready: list[dict] = []
        self.links: dict[str, str] = {}
        self.t0_monotonic_ns: int | None = None
        try:
            for i, hosted in enumerate(self.vehicles):
                proc = subprocess.Popen(
                    [sys.executable, "-m", "navtwin.emulator.workers"], stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE, text=True, start_new_session=False)
                self.procs.append(proc)
                proc.stdin.write(json.dumps({
                    "scenario": scenario.to_toml(), "seed": self.seed, "speed": speed,
                    "duration_s": duration_s, "timing": timing, "vehicles": hosted,
                    "link_dir": os.path.join(self._private, str(i + 1)), "parent": os.getpid(),
                    "progress": f"worker {i + 1}: " if progress else None}) + "\n")
                proc.stdin.flush()
                threading.Thread(target=self._read, args=(i, proc), daemon=True).start()
            for _ in self.procs:
                i, line = self._lines.get()
                if line is None or "ready" not in line:
                    raise RunError(self._failure(i, line))
                self.ready.append(line)
            self.ready.sort(key=lambda r: r["worker"])
            pts = {name: path for r in self.ready for name, path in r["pts"].items()}
            for name in self.order:
                self.links[name] = str(self.link_dir.link(name, pts[name]))
            self.pts = {name: pts[name] for name in self.order}
        except BaseException:
            self.close()
            raise

    def _read(self, i: int, proc) -> None:
        for text in proc.stdout:
            try:
                line = json.loads(text)
            except ValueError:
                continue  # not ours
            self._lines.put((i, {**line, "worker": i}))
        self._lines.put((i, None))

    def _failure(self, i: int, line: dict | None) -> str:
        """The one line for worker *i*'s end without its ready or done line."""
        what = f"worker {i + 1} (vehicles {', '.join(map(str, self.vehicles[i]))})"
        if line is not None and "error" in line:
            return f"{what}: {line['error']}"
        code = self.procs[i].wait()
        return (f"{what} ended with status {code} before its summary; the other workers were "
                f"stopped (see its messages above, or run fewer vehicles per worker)")

    def info(self) -> dict:
        """The ready line: every worker's ports under the one link directory."""
        first = self.ready[0]
        return {"ready": True, "ports": dict(self.links), "pts": dict(self.pts),
                "scenario": self.scenario.name, "seed": self.seed,
                "speed": speed_name(self.speed), "duration_s": first["duration_s"],
                **({"timing": first["timing"]} if "timing" in first else {}),
                "workers": len(self.procs), "workers_chosen": self.chosen,
                "vehicles_per_worker": self.vehicles,
                "link_dir": str(self.link_dir.path), "control": None, "tap": None,
                "pid": os.getpid(), "worker_pids": [p.pid for p in self.procs]}

    def run(self, stop: threading.Event) -> dict:
        """Start every worker on one clock, wait for their done lines (stopping them all on
        *stop* or when one fails) and return the merged summary; RunError if one failed."""
        self.t0_monotonic_ns = None if self.speed is None else time.monotonic_ns() + START_NS
        for proc in self.procs:
            proc.stdin.write(json.dumps({"t0_monotonic_ns": self.t0_monotonic_ns}) + "\n")
            proc.stdin.flush()
        done: dict[int, dict] = {}
        failure, stopping = None, False
        while len(done) < len(self.procs) and not (failure and self._all_ended(done)):
            if stop.is_set() and not stopping:
                stopping = True
                self._signal(signal.SIGTERM)
            try:
                i, line = self._lines.get(timeout=0.1)
            except queue.Empty:
                continue
            if line is not None and line.get("done"):
                done[i] = line
            elif i not in done and failure is None:
                failure = self._failure(i, line)
                self._signal(signal.SIGTERM)
                stopping = True
        if failure is not None:
            raise RunError(failure)
        return self._merge([done[i] for i in range(len(self.procs))])

    def _all_ended(self, done: dict) -> bool:
        return all(i in done or p.poll() is not None for i, p in enumerate(self.procs))

    def _signal(self, sig: int) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(sig)

    def _merge(self, summaries: list[dict]) -> dict:
        ports = {name: e for s in summaries for name, e in s["ports"].items()}
        faults: dict[str, dict] = {}
        for s in summaries:
            for kind, totals in s["faults"].items():
                mine = faults.setdefault(kind, {})
                for key, value in totals.items():
                    mine[key] = mine.get(key, 0) + value
        first = summaries[0]
        return {"done": True, "scenario": first["scenario"], "seed": first["seed"],
                "speed": first["speed"], **({"timing": first["timing"]} if "timing" in first else {}),
                "virtual_s": min(s["virtual_s"] for s in summaries),
                "interrupted": any(s["interrupted"] for s in summaries),
                "ports": {name: ports[name] for name in self.order if name in ports},
                "faults": faults, "workers": len(summaries),
                "t0_monotonic_ns": self.t0_monotonic_ns if self.speed is not None else None}

    def close(self) -> None:
        """Stop the workers still running, remove the links and the private directory."""
        self._signal(signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            for f in (proc.stdin, proc.stdout):
                try:
                    f.close()
                except OSError:
                    pass
        self.procs = []
        if self.link_dir is not None:
            self.link_dir.close()
            self.link_dir = None
        try:
            os.rmdir(self._private)  # each worker removed its own directory
        except OSError:
            pass

    def __enter__(self) -> "Workers":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def main() -> int:
    """A worker: the vehicles its JSON line on stdin names (module docstring)."""
    import tomllib

    from .pty import LinkDirError
    from .runner import Emulation
    from .scenario import ScenarioError, parse_scenario

    def emit(obj: dict) -> None:
        sys.stdout.write(json.dumps(obj, separators=(",", ":")) + "\n")
        sys.stdout.flush()

    stop = threading.Event()
    handler = stopper(stop)
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, handler)
    spec = json.loads(sys.stdin.readline())
    # a parent killed outright (SIGKILL) cannot stop its workers: the kernel does, as SIGTERM
    if not die_with_parent(spec["parent"], signal.SIGTERM):
        return 0  # it died before that was asked
    prefix = spec["progress"]
    try:
        sc = parse_scenario(tomllib.loads(spec["scenario"]), "worker")
        emu = Emulation(sc, spec["seed"], speed=spec["speed"], duration_s=spec["duration_s"],
                        link_dir=spec["link_dir"], timing=spec["timing"], vehicles=spec["vehicles"],
                        progress=None if prefix is None else
                        (lambda line: print(prefix + line, file=sys.stderr, flush=True)))
    except (LinkDirError, RunError, ScenarioError) as e:
        emit({"error": str(e)})
        return 2
    with emu:
        emu.prepare()
        emit(emu.info())
        go = sys.stdin.readline()
        if not go:
            return 0  # the parent went away before the start
        summary = emu.run(stop, start_monotonic_ns=json.loads(go)["t0_monotonic_ns"])
    emit(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
