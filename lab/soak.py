"""The live soak: the lab for many minutes with the misuse of ordinary days, measured.

``navtwin bench lab-soak [--seconds 600] [--faults] [--dir DIR]`` runs
``navtwin emulate`` in real time on a long office scenario (the loop driven again and again)
and ``navtwin host`` on its PTYs, each its own process as users run them, and meanwhile:

* a second reader (pyserial, not exclusive, as ``cat`` or ``socat`` would be) opens one of
  the host's ports every ``reader_period_s``, reads for a second and closes it again,
  alternating between ``xbee`` and ``nanoloc``: the bytes it takes are lost to the host, as
  on a real line, but the host must neither drop the port nor stall;
* half way through, the emulator is killed with SIGKILL and a new one started on the same
  link directory (the vehicle is back at its start): the host must follow the new links and
  every track must come back.

With ``faults`` (``--faults``) the scenario also injects, periodically, the fault kinds of
:data:`SOAK_FAULTS` (line faults on both of the host's ports, an RF fade, an anchor outage,
value errors, a board reset), the host records, and at the end the run is audited
(lab.audit): nothing the host lost may be unaccounted for. The emulator is then not
restarted (a host recording spans one emulator run for the audit; restarts have their own
test), the second reader still takes bytes (the audit sees them as unseen, not lost, and
as ``second_reader`` where the host saw it take them).

It reports the host's and the emulator's resident memory after warm-up and at the end, the
host's IMU rate per status period (and the worst period outside the restart), what the
second reader took, the host's port events, and per track the recovery time after the
restart: the first time after which its error against the new emulator's truth stays below
``max(2 x its p95 error over the same stretch of the first run, 0.5 m)`` for 5 s.
"""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from navtwin.emulator.api import Lab, command

from . import evaluate
from .audit import audit

WARMUP_S = 60.0  # memory is compared from here: imports, buffers and caches are in place
HOLD_S = 5.0  # an error must stay under its threshold this long to count as recovered
FLOOR_M = 0.5


#: the faulted soak's [[faults]]: each kind every 2 to 5 minutes, a few seconds long
SOAK_FAULTS = """
[[faults]]
kind = "bit_errors"
port = "xbee"
ber = 2e-5
start_s = 30
end_s = 40
repeat_s = 120

[[faults]]
kind = "byte_drop"
port = "nanoloc"
probability = 1e-3
start_s = 45
end_s = 55
repeat_s = 120

[[faults]]
kind = "garbage"
port = "xbee"
start_s = 60
end_s = 70
repeat_s = 120

[[faults]]
kind = "latency"
port = "nanoloc"
delay_s = 0.003
jitter_s = 0.002
start_s = 75
end_s = 85
repeat_s = 120

[[faults]]
kind = "link_fade"
attempt_loss = 0.9
start_s = 90
end_s = 92
repeat_s = 120

[[faults]]
kind = "anchor_outage"
anchor = 3
start_s = 100
end_s = 105
repeat_s = 180

[[faults]]
kind = "range_value_error"
anchor = 2
probability = 0.3
start_s = 110
end_s = 115
repeat_s = 180

[[faults]]
kind = "board_reset"
start_s = 150
end_s = 150.5
repeat_s = 300
"""


def _scenario(path: Path, seconds: float, faults: bool = False) -> Path:
    """Office, its loop driven as often as *seconds* needs (a lap is about 62 s); with
    *faults*, SOAK_FAULTS too."""
    laps = int(seconds // 55) + 2
    path.write_text(f'base = "office"\nname = "office-soak"\nduration_s = {seconds + 30.0}\n'
                    f"\n[trajectory]\nloops = {laps}\n" + (SOAK_FAULTS if faults else ""))
    return path


def rss_kb(pid: int, field: str = "VmRSS") -> int | None:
    """Process *pid*'s resident set now (VmRSS) or its peak (VmHWM), kB (None: it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


class SecondReader(threading.Thread):
    """Opens a port every *period* s, reads for a second, closes it."""

    def __init__(self, links: dict[str, str], period: float, stop: threading.Event) -> None:
        super().__init__(name="navtwin-soak-reader", daemon=True)
        self.links, self.period, self.stop = links, period, stop
        self.opens = {name: 0 for name in links}
        self.taken = {name: 0 for name in links}
        self.failed = 0  # opens that failed (the emulator restarting: no link)
        self.lost_races = 0  # reads that found the bytes taken by the host first

    def run(self) -> None:
        import serial

        names = list(self.links)
        k = 0
        while not self.stop.wait(self.period - 1.0):
            name = names[k % len(names)]
            k += 1
            try:
                ser = serial.Serial(self.links[name], 115200, timeout=0.1)
            except (serial.SerialException, OSError):
                self.failed += 1
                continue
            with ser:
                self.opens[name] += 1
                end = time.monotonic() + 1.0
                while time.monotonic() < end:
                    try:
                        self.taken[name] += len(ser.read(4096))
                    except serial.SerialException:  # "readiness to read but no data"
                        self.lost_races += 1
                        time.sleep(0.001)  # pyserial returns at once: do not spin a core
                    except OSError:  # the port went away under the reader
                        break


def _recovery(truth: dict, est: dict, offset: float, t_from: float, threshold: float) -> float | None:
    """Seconds after *t_from* (host time) until the error stays under *threshold* for HOLD_S."""
    t = est["t"]
    keep = (t >= t_from) & (t + offset <= truth["t"][-1])
    t, err = t[keep], evaluate.error(truth, est, offset)[keep]
    good_since = None
    for ti, e in zip(t, err):
        if e >= threshold:
            good_since = None
        elif good_since is None:
            good_since = ti
        elif ti - good_since >= HOLD_S:
            return float(good_since - t_from)
    return None


def _p95(truth: dict, est: dict, offset: float, t0: float, t1: float,
         host_before: float) -> float | None:
    """p95 error of the estimates before *host_before* (host time) whose scenario time is
    in [t0, t1)."""
    t = est["t"] + offset
    keep = (t >= t0) & (t < t1) & (est["t"] < host_before)
    if not keep.any():
        return None
    return float(np.percentile(evaluate.error(truth, est, offset)[keep], 95))


def soak(seconds: float = 600.0, reader_period_s: float = 4.0, seed: int = 1,
         directory: str | os.PathLike | None = None, progress=None,
         faults: bool = False) -> dict:
    """Run the soak; returns its figures (see the module docstring)."""
    d = Path(directory or tempfile.mkdtemp(prefix="navtwin-soak-"))
    d.mkdir(parents=True, exist_ok=True)
    links_dir = d / "links"
    scenario = _scenario(d / "soak.toml", seconds, faults)
    half = math.inf if faults else seconds / 2
    say = progress or (lambda msg: None)

    def start_emulator(tag: str) -> tuple[Lab, int]:
        lab = Lab(command(str(scenario), seed=seed, speed="realtime", link_dir=links_dir,
                          record=d / tag), ready_timeout=120.0)
        return lab, time.monotonic_ns()

    first, first_ready = start_emulator("emulator-1")
    log = open(d / "host.log", "wb")
    host = subprocess.Popen(
        [sys.executable, "-m", "navtwin", "host", "--xbee", first.ports["xbee"],
         "--nanoloc", first.ports["nanoloc"], "--config", "office", "--status-period", "1",
         "--out", str(d / "estimates.jsonl"), *(["--record", str(d / "host")] if faults else [])],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log)
    stop = threading.Event()
    reader = SecondReader({"xbee": first.ports["xbee"], "nanoloc": first.ports["nanoloc"]},
                          reader_period_s, stop)
    reader.start()
    rss: list[tuple[float, int | None, int | None]] = []
    second = None
    t_start = time.monotonic()
    kill_mono = second_ready = None
    try:
        while (el := time.monotonic() - t_start) < seconds:
            if second is None and el >= half:
                first.process.send_signal(signal.SIGKILL)
                first.process.wait()
                kill_mono = time.monotonic_ns()
                first.close()
                say(f"soak: {el:.0f} s: emulator killed, restarting on {links_dir}")
                second, second_ready = start_emulator("emulator-2")
            emu = second or first
            rss.append((el, rss_kb(host.pid), rss_kb(emu.process.pid)))
            if int(el) % 30 == 0:
                say(f"soak: {el:.0f} / {seconds:g} s, host RSS {rss[-1][1]} kB")
            time.sleep(1.0)
    finally:
        stop.set()
        reader.join(timeout=5)
        done = second.stop() if second is not None else first.stop()
        (second or first).close()
        host.send_signal(signal.SIGTERM)
        host.wait(timeout=30)
        log.close()
    lines = [json.loads(x) for x in (d / "host.log").read_text().splitlines() if x.startswith("{")]
    summary = next((x["summary"] for x in reversed(lines) if "summary" in x), {})
    status = [x["status"] for x in lines if "status" in x]
    host_t0 = summary.get("t0_monotonic_ns")
    audited = {}
    if faults:
        result = audit(d / "emulator-1", d / "host")
        audited = {"faults": done.get("faults"), "audit": {
            "ok": result["ok"], "ledger_entries": result["ledger_entries"],
            "ports": {p: {k: r[k] for k in ("frames", "accepted", "rejected_bytes", "injections",
                                            "unseen_bytes", "unseen", "problems")}
                      for p, r in result["ports"].items()}},
            "reinit": [v["estimator"]["reinit"] for v in summary.get("vehicles", [])]}
    return {"benchmark": "lab-soak", "seconds": seconds, "dir": str(d), **audited,
            **_memory(rss), **_rates(status, host_t0, kill_mono, second_ready),
            "second_reader": {"opens": reader.opens, "bytes_taken": reader.taken,
                              "open_failed": reader.failed, "lost_races": reader.lost_races},
            "events": _events(status),
            "recovery_s": _tracks(d, host_t0, first_ready, kill_mono, second_ready, done)}


def _memory(rss) -> dict:
    def at(i, t):
        vals = [r[i] for r in rss if r[0] >= t and r[i]]
        return vals[0] if vals else None

    host = [r[1] for r in rss if r[1]]
    out = {"host_rss_kb": {"after_warmup": at(1, WARMUP_S), "end": host[-1] if host else None,
                           "max": max(host) if host else None}}
    emu2 = [r[2] for r in rss if r[2]]
    out["emulator_rss_kb"] = {"after_warmup": at(2, WARMUP_S), "end": emu2[-1] if emu2 else None}
    h = out["host_rss_kb"]
    if h["after_warmup"] and h["end"]:
        h["growth_kb"] = h["end"] - h["after_warmup"]
    return out


def _rates(status, host_t0, kill_ns, ready_ns) -> dict:
    """The host's IMU samples per second in each status period, outside the restart gap."""
    if host_t0 is None:
        return {}
    gap = ((kill_ns - host_t0) / 1e9, (ready_ns - host_t0) / 1e9 + 10.0) if kill_ns else None
    rates = [s["imu_per_s"] for s in status if "imu_per_s" in s and s.get("t_s", 0) > 15
             and not (gap and gap[0] - 1 <= s["t_s"] <= gap[1])]
    out = {"imu_per_s": {"median": float(np.median(rates)) if rates else None,
                         "min": min(rates) if rates else None, "periods": len(rates)}}
    if gap:  # the first full status period of IMU data from the new emulator
        back = [s["t_s"] - 1.0 for s in status if s.get("t_s", 0) > gap[0] + 1
                and s.get("imu_per_s", 0) >= 90]
        out["imu_back_after_restart_s"] = round(back[0] - (ready_ns - host_t0) / 1e9, 2) if back else None
    return out


def _events(status) -> dict:
    out: dict[str, int] = {}
    for s in status:
        if "event" in s:
            key = s["event"] + (f":{s['port']}" if "port" in s else "")
            out[key] = out.get(key, 0) + 1
    return out


def _tracks(d: Path, host_t0, first_ready, kill_ns, second_ready, done: dict) -> dict:
    """Per track: seconds from the restart until its error stays under its threshold."""
    est_path, truth_path = d / "estimates.jsonl", d / "emulator-2" / "truth.csv"
    if not (host_t0 and second_ready and done.get("t0_monotonic_ns") and truth_path.is_file()):
        return {}
    estimates = evaluate.load_estimates(est_path)
    # both emulators ran the same scenario and seed: one truth serves both runs
    truth = evaluate.load_truth(truth_path)
    # the first emulator was killed: its scenario time 0 is about when it said ready
    off1 = (host_t0 - first_ready) / 1e9
    off2 = (host_t0 - done["t0_monotonic_ns"]) / 1e9
    restart = (second_ready - host_t0) / 1e9
    killed = (kill_ns - host_t0) / 1e9
    out = {}
    for name, est in sorted(estimates.items()):
        # the normal error: the same 10-40 s of scenario time in the first run
        normal = _p95(truth, est, off1, 10.0, 40.0, killed)
        threshold = max(2 * normal, FLOOR_M) if normal is not None else None
        out[name] = {"normal_p95_m": normal, "threshold_m": threshold,
                     "recovery_s": None if threshold is None else
                     _recovery(truth, est, off2, restart, threshold)}
    return out
