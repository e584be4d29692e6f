"""004's LS-SVM bridging on outage-bridging in four forms, beside BP and the coasting HF: mean
horizontal error (m) in each WSN outage over seeds 1-20, 95 % Student-t intervals and the
paired differences against BP: the figures of docs/results.md's "LS-SVM's inputs".

    python docs/examples/lssvm_inputs.py [SEEDS] [WORKERS]

The forms, each the shipped host config with [filters."hinf+lssvm"] changed: 004's sigma =
eta = 1000 on the raw inputs (the shipped one), 004's two-subset validation on the raw
inputs (tune), and both again with the inputs standardised (standardise). Each seed runs in
memory once per form (the emulator's bytes are the same for every form).
"""
import dataclasses
import sys
from multiprocessing import Pool

import numpy as np
from scipy import stats

from navtwin.host import config as host_config
from navtwin.host.output import estimate_line
from navtwin.lab import areas, evaluate
from navtwin.lab.run import run_in_memory, truth

SCENARIO = "outage-bridging"
FORMS = {"004: 1000/1000, raw inputs": {},
         "004: validated, raw inputs": {"tune": True},
         "1000/1000, standardised": {"standardise": True},
         "validated, standardised": {"tune": True, "standardise": True}}
WINDOWS = ("outage1", "outage2")


def ci(x) -> str:
    x = np.asarray(x)
    h = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return f"{x.mean():.2f} ± {h:.2f}"


def seed_row(seed: int) -> dict:
    """{form or track: (outage 1, outage 2) mean horizontal error} for one seed."""
    from navtwin.emulator.scenario import load_scenario

    sc, base = load_scenario(SCENARIO), host_config.load(SCENARIO)
    tr = truth(sc, seed)
    row = {}
    for k, (form, change) in enumerate(FORMS.items()):
        settings = dict(base.settings)
        settings["hinf+lssvm"] = dataclasses.replace(settings["hinf+lssvm"], **change)
        cfg = dataclasses.replace(base, settings=settings)
        tracks = ("hinf", "hinf+lssvm", "hinf+bp") if k == 0 else ("hinf+lssvm",)
        est, _ = run_in_memory(sc, seed, config=cfg, filters=tracks)
        w = areas.window_errors(areas.boxes(sc), tr, evaluate.load_estimates(map(estimate_line, est)))
        row[form] = tuple(w["hinf+lssvm"][f"{n}_mean"] for n in WINDOWS)
        if k == 0:
            row["BP (hinf+bp)"] = tuple(w["hinf+bp"][f"{n}_mean"] for n in WINDOWS)
            row["HF coasting (hinf)"] = tuple(w["hinf"][f"{n}_mean"] for n in WINDOWS)
    return row


def main(seeds: int = 20, workers: int = 2) -> None:
    with Pool(workers) as pool:
        rows = pool.map(seed_row, range(1, seeds + 1))
    print(f"{SCENARIO}, seeds 1..{seeds}: mean horizontal error (m) in each outage; minus BP's, paired")
    print(f"{'':28s} {'outage 1':>16s} {'outage 2':>16s} {'- BP, outage 1':>16s} {'- BP, outage 2':>16s}")
    for name in rows[0]:
        v = np.array([r[name] for r in rows])
        bp = np.array([r["BP (hinf+bp)"] for r in rows])
        print(f"{name:28s} {ci(v[:, 0]):>16s} {ci(v[:, 1]):>16s} {ci(v[:, 0] - bp[:, 0]):>16s} "
              f"{ci(v[:, 1] - bp[:, 1]):>16s}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
