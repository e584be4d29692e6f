"""Start-up cost of the ``navtwin`` command (``navtwin bench startup``, docs/performance.md).

CPU-seconds (user + system) a process spends before it has done what it was started for:
``navtwin --version`` and ``navtwin ctl status`` (against a lab this benchmark starts) to
their exit, ``navtwin emulate`` to its ready line. The peer is ``python -c "import numpy"``
with the same interpreter, measured in the same rounds, interleaved; figures are medians.
Every test process, ``ctl`` call and lab start pays this, so the goal is each within 2x of
the peer.

Bytecode is cached, as after any install (pip compiles it; an editable install writes it at
the first import): the commands run with a private cache (``PYTHONPYCACHEPREFIX`` in the
benchmark's temporary directory), filled by one unmeasured round, whatever
``PYTHONDONTWRITEBYTECODE`` the caller has; without a cache every start compiles navtwin's
own modules again (0.02-0.07 CPU-s for ``emulate``, docs/performance.md), while numpy's come
precompiled.
"""
from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

NAVTWIN = (sys.executable, "-m", "navtwin")
PEER = (sys.executable, "-c", "import numpy")
GOAL = 2.0


class StartupError(RuntimeError):
    """A command of the benchmark did not do what it was started for (the message says which)."""


def cached_bytecode(cache: str) -> dict:
    """The commands' environment: this one with its bytecode cached in *cache*."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, "PYTHONPYCACHEPREFIX": cache}


def cpu_to_exit(argv, env=None) -> float:
    """Children's CPU-seconds of one run of *argv* to its exit (it must exit 0)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=120,
                          env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise StartupError(f"{' '.join(argv[2:])}: exit {done.returncode}: "
                           f"{done.stderr.decode(errors='replace').strip()}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _cpu_so_far(pid: int) -> float:
    """CPU-seconds of the running process *pid*, all its threads (/proc, clock ticks)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_lab(link_dir: str, speed: str = "realtime",
              env=None) -> tuple[subprocess.Popen, float]:
    """``navtwin emulate`` on office in the background, and its CPU-seconds to the ready line."""
    proc = subprocess.Popen((*NAVTWIN, "emulate", "--scenario", "office", "--quiet",
                             "--speed", speed, "--link-dir", link_dir), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    cpu = _cpu_so_far(proc.pid) if line else 0.0
    try:
        ready = json.loads(line).get("ready") is True
    except ValueError:
        ready = False
    if not ready:
        stop_lab(proc)
        raise StartupError(f"navtwin emulate gave no ready line: {line.strip() or 'nothing'} "
                           f"{proc.stderr.read().strip()}")
    return proc, cpu


def stop_lab(proc: subprocess.Popen) -> None:
    proc.terminate()
    proc.communicate(timeout=60)


def startup(runs: int = 7) -> dict:
    """Medians of *runs* interleaved rounds: the peer, --version, ctl status, emulate (one
    round before them unmeasured: it fills the bytecode cache)."""
    cpu: dict[str, list[float]] = {"peer": [], "version": [], "ctl_status": [],
                                   "emulate_ready": []}
    with tempfile.TemporaryDirectory(prefix="navtwin-startup-") as tmp:
        env = cached_bytecode(os.path.join(tmp, "bytecode"))
        # the lab that ctl status asks, slowed so that its 70 s outlast any load
        lab, _ = start_lab(os.path.join(tmp, "lab"), speed="0.01", env=env)
        try:
            for _ in range(1 + runs):
                used = {"peer": cpu_to_exit(PEER, env),
                        "version": cpu_to_exit((*NAVTWIN, "--version"), env),
                        "ctl_status": cpu_to_exit((*NAVTWIN, "ctl", "status", "--link-dir",
                                                   os.path.join(tmp, "lab")), env)}
                proc, used["emulate_ready"] = start_lab(os.path.join(tmp, "ready"), env=env)
                stop_lab(proc)
                for name, value in used.items():
                    cpu[name].append(value)
        finally:
            stop_lab(lab)
        cpu = {name: values[1:] for name, values in cpu.items()}  # the first filled the cache
    peer = statistics.median(cpu["peer"])
    out = {"benchmark": "startup", "runs": runs, "goal": f"each <= {GOAL}x the peer",
           "peer": {"command": "python -c 'import numpy'", "cpu_s": round(peer, 3)},
           "load_average": [round(load, 1) for load in os.getloadavg()]}  # at the end
    for name, values in cpu.items():
        if name != "peer":
            median = statistics.median(values)
            out[name] = {"cpu_s": round(median, 3), "to_peer": round(median / peer, 2),
                         "within_goal": median <= GOAL * peer}
    return out
