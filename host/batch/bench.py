"""``navtwin bench batch``: filter steps per CPU-second across a batch of N seeds, beside the
per-filter path in the same run (issue 23 item 6; its goal: 1,000,000 a second on one core,
for both).

Two steps, as the issue words them, on host.bench_filters' office state:

- ``kf_step``: a KF step, predict over 10 ms then the 2-D SINS acceleration update
  (H = [0 0 I], R = 1.5^2 I, each seed its own z);
- ``errorstate_predict``: an 11-state error-state predict (tc's: 7 nav states and 4 NLOS
  random walks) over 10 ms, each seed its own specific force.

For each N the batch filter steps all N seeds at once; the per-filter path steps N
KalmanFilter / ErrorStateFilter objects one after another (what a sweep does today). Rates
are seed-steps per CPU-second (``time.process_time``): each timing runs whole steps until
``seconds`` of CPU have passed, and the figure is the median over ``repeats`` timings, the
per-filter and batch timings of every N interleaved so a drift of the machine weighs on both.
The ratio is batch over per-filter. The timings run in a child process started with
OPENBLAS_NUM_THREADS, OMP_NUM_THREADS and MKL_NUM_THREADS = 1 (a BLAS reads them when it
loads, before any benchmark could set them), so CPU time is one core's.
"""
from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import between, counts, key, takes

GOAL = 1_000_000  # seed-steps per CPU-second on one core (issue 23)
ONE_THREAD = {v: "1" for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
EXTRA = 4  # tc's NLOS states: the 11-state filter


@dataclass(frozen=True)
class Batch:
    """batch's settings."""
    sizes: str | None = key(None, "", "the batch sizes N, comma-separated; none = "
                            "1,16,256,1024,4096 (1,256 quick)",
                            counts(1, 65536, "1,256,4096"))
    repeats: int | None = key(None, "", "timings of each, the median given; none = 5 (3 quick)",
                              between(1, 100))
    seconds: float | None = key(None, "s", "CPU time of one timing; none = 0.2 (0.03 quick)",
                                between(0.001, 60))


def kf_steps(n: int) -> tuple[Callable[[], None], Callable[[], None]]:
    """(one batch step of n seeds, n per-filter steps): predict, acceleration update."""
    from navtwin.host.bench_filters import DT, P0, X0
    from navtwin.host.filters import ACCELERATION, ConstantAcceleration, KalmanFilter

    from .kf import BatchKalmanFilter

    model = ConstantAcceleration(0.5)
    rng = np.random.default_rng(0)
    z = np.array([0.05, -0.02]) + rng.normal(0, 0.3, (n, 2))
    R = 1.5**2 * np.eye(2)
    batch = BatchKalmanFilter(np.tile(X0, (n, 1)), np.tile(P0, (n, 1, 1)), model)
    alone = [KalmanFilter(X0, P0, model) for _ in range(n)]

    def batched():
        batch.predict(DT)
        batch.update(z, R, ACCELERATION)

    def per_filter():
        for f, zs in zip(alone, z):
            f.predict(DT)
            f.update(zs, R, ACCELERATION)
    return batched, per_filter


def errorstate_predicts(n: int) -> tuple[Callable[[], None], Callable[[], None]]:
    """(one batch predict of n seeds, n per-filter predicts), 11 states, each seed's f_n."""
    from navtwin.host.bench_filters import DT
    from navtwin.host.filters.errorstate import NAV, ErrorStateFilter

    from .errorstate import BatchErrorStateFilter

    rng = np.random.default_rng(0)
    f_n = np.array([0.05, 0.04, 9.7952]) + rng.normal(0, 0.3, (n, 3))
    forces = [tuple(map(float, f)) for f in f_n]  # as the strapdown gives it: floats
    P0 = np.diag([0.2, 0.2, 0.05, 0.05, 0.01, 0.01, 0.02] + [0.3] * EXTRA) ** 2
    noise = dict(gyro_psd=(np.radians(0.3) / 60) ** 2, accel_psd=(0.05 / 60) ** 2, extra=EXTRA,
                 extra_psd=0.01)
    assert P0.shape == (NAV + EXTRA,) * 2
    batch = BatchErrorStateFilter(np.tile(P0, (n, 1, 1)), **noise)
    alone = [ErrorStateFilter(P0, **noise) for _ in range(n)]

    def batched():
        batch.predict(DT, f_n)

    def per_filter():
        for f, fs in zip(alone, forces):
            f.predict(DT, fs)
    return batched, per_filter


STEPS = {"kf_step": kf_steps, "errorstate_predict": errorstate_predicts}


def rate(step: Callable[[], None], seeds: int, seconds: float) -> float:
    """Seed-steps per CPU-second of *step* (each call steps *seeds*), over >= *seconds*."""
    calls = 0
    t0 = time.process_time()
    while True:
        step()
        calls += 1
        used = time.process_time() - t0
        if used >= seconds:
            return calls * seeds / used


def measure(sizes: list[int], repeats: int, seconds: float) -> dict:
    """Every step's rates at each N (in this process: its BLAS threads are the caller's)."""
    out = {}
    for name, make in STEPS.items():
        steps = {n: make(n) for n in sizes}
        runs = {n: ([], []) for n in sizes}
        for _ in range(repeats):
            for n, (batched, per_filter) in steps.items():
                runs[n][0].append(rate(batched, n, seconds))
                runs[n][1].append(rate(per_filter, n, seconds))
        by_n = {}
        for n, (b, p) in runs.items():
            b, p = float(np.median(b)), float(np.median(p))
            by_n[str(n)] = {"batch_steps_per_s": round(b), "per_filter_steps_per_s": round(p),
                            "ratio": round(b / p, 2)}
        best = max(by_n, key=lambda k: by_n[k]["batch_steps_per_s"])
        out[name] = {"by_n": by_n, "best_n": int(best),
                     "goal_met": by_n[best]["batch_steps_per_s"] >= GOAL}
    return out


def batch(settings: Batch, quick: bool) -> dict:
    """The figures of ``navtwin bench batch``, timed in a one-thread child process."""
    sizes = [int(v) for v in (settings.sizes or ("1,256" if quick else "1,16,256,1024,4096")).split(",")]
    job = {"sizes": sizes, "repeats": settings.repeats or (3 if quick else 5),
           "seconds": settings.seconds or (0.03 if quick else 0.2)}
    done = subprocess.run([sys.executable, "-m", "navtwin.host.batch.bench"], input=json.dumps(job),
                          capture_output=True, text=True, env={**os.environ, **ONE_THREAD})
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"the batch benchmark's child process failed: {last}")
    return {"benchmark": "batch", **json.loads(done.stdout), "goal_steps_per_s": GOAL,
            "cpu_time": "time.process_time of the child process",
            "threads": "one: " + ", ".join(f"{k}=1" for k in ONE_THREAD) + " in the child process",
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                       f"numpy {np.__version__}", "settings": job}


def benchmarks() -> dict:
    """``navtwin bench batch`` (a set of navtwin.cli.bench.SETS)."""
    @takes(Batch)
    def batch_bench(quick: bool, s: Batch) -> dict:
        """host: KF steps and error-state predicts per CPU-second across N seeds beside the per-filter path (goal >= 1e6 on one core)"""
        return batch(s, quick)

    return {"batch": batch_bench}


def main() -> int:
    """The child: the job's settings as JSON on stdin, the figures as JSON on stdout."""
    job = json.loads(sys.stdin.read())
    seen = {k: os.environ.get(k) for k in ONE_THREAD}  # what the BLAS read when it loaded
    print(json.dumps({**measure(job["sizes"], job["repeats"], job["seconds"]), "threads_env": seen}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
