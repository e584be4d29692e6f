"""Two sweeps of one scenario compared seed by seed: for each filter both have, its per-seed
mean, max and RMS error and NEES in each (mean over seeds, ± the 95 % Student-t half-width)
and the paired difference A - B over the seeds both computed (decided where its interval
excludes 0). For two code versions or configs run on the same seeds: the figures of
docs/results.md's "Paper 001, where we agree and where not" (fatci before and after its sets
came from the calibration).

    navtwin sweep --scenario corridor --seeds 1..30 --filters tc,fatci --out A   # one version
    navtwin sweep --scenario corridor --seeds 1..30 --filters tc,fatci --out B   # the other
    python docs/examples/paired_sweeps.py A B
"""
import sys
from pathlib import Path

from navtwin.lab.evaluate import mean_ci
from navtwin.lab.sweep import read_out

FIGURES = ("mean", "max", "rms", "nees_mean")


def cells(out: str) -> dict:
    """(filter, seed) -> the row of each cell computed ok in the sweep directory *out*."""
    _, rows = read_out(Path(out))
    return {(r["filter"], r["seed"]): r for r in rows if r["status"] == "ok"}


def main(a: str, b: str) -> None:
    ca, cb = cells(a), cells(b)
    filters = sorted({f for f, _ in ca} & {f for f, _ in cb})
    print(f"A = {a}, B = {b}; per-seed figures, mean ± 95 % t half-width; A - B paired by seed")
    print(f"{'filter':8} {'figure':10} {'seeds':>5} {'A':>16} {'B':>16} {'A - B':>18}  decides")
    for f in filters:
        seeds = sorted(s for g, s in ca if g == f and (f, s) in cb)
        for m in FIGURES:
            va = [ca[f, s][m] for s in seeds]
            vb = [cb[f, s][m] for s in seeds]
            d, h = mean_ci([x - y for x, y in zip(va, vb)])
            decides = "not decided" if not abs(d) > h else ("A lower" if d < 0 else "B lower")
            print(f"{f:8} {m:10} {len(seeds):5} {'%.4f ± %.4f' % mean_ci(va):>16} "
                  f"{'%.4f ± %.4f' % mean_ci(vb):>16} {f'{d:+.4f} ± {h:.4f}':>18}  {decides}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python docs/examples/paired_sweeps.py SWEEP_DIR_A SWEEP_DIR_B")
    main(*sys.argv[1:])
