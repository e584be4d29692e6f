"""Max position error per track inside corridor-outage's two WSN outages (anchor 2 silent
from 18 to 23 s and from 40 to 45 s, each window taken 1 s longer for the recovery) and
elsewhere after the alignment, over seeds 1-20, with 95 % Student-t intervals: the figures
of docs/results.md's "Corridor with WSN outages".

    python docs/examples/outage_windows.py [SEEDS]
"""
import sys

import numpy as np
from scipy import stats

from navtwin.host.output import estimate_line
from navtwin.lab import evaluate
from navtwin.lab.run import run_in_memory, truth

TRACKS = ("wsn", "kf", "ekf", "lc", "tc", "fatci")
WINDOWS = ((18.0, 24.0), (40.0, 46.0))


def ci(x) -> str:
    x = np.asarray(x)
    h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return f"{x.mean():.3f} ± {h:.3f}"


def main(seeds: int = 20) -> None:
    inside = {f: [] for f in TRACKS}
    outside = {f: [] for f in TRACKS}
    for seed in range(1, seeds + 1):
        estimates, _ = run_in_memory("corridor-outage", seed, filters=TRACKS)
        tr = truth("corridor-outage", seed)
        for f, e in evaluate.load_estimates(map(estimate_line, estimates)).items():
            err, t = evaluate.error(tr, e), e["t"]
            win = np.zeros(t.size, bool)
            for a, b in WINDOWS:
                win |= (t >= a) & (t < b)
            inside[f].append(err[win].max())
            outside[f].append(err[~win & (t > 10)].max())
    print(f"{'track':6} {'max in the outages m':>22} {'max elsewhere m':>18}   ({seeds} seeds)")
    for f in TRACKS:
        print(f"{f:6} {ci(inside[f]):>22} {ci(outside[f]):>18}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
