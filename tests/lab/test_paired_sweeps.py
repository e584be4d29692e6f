"""docs/examples/paired_sweeps.py: two sweeps compared seed by seed."""
import runpy

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from navtwin.lab.evaluate import mean_ci
from navtwin.lab.sweep import META_KEY, METRICS, SCHEMA

from ..helpers import ROOT

SCRIPT = ROOT / "docs" / "examples" / "paired_sweeps.py"


def _sweep(out, means: dict[int, float]) -> None:
    """A sweep directory of one filter, fatci, with the per-seed mean errors *means*."""
    out.mkdir()
    rows = [{"scenario": "corridor", "seed": s, "filter": "fatci", "status": "ok", "error": None,
             **dict.fromkeys(METRICS, 1.0), "n": 10, "mean": m} for s, m in means.items()]
    with pq.ParquetWriter(out / "part-0000.parquet", SCHEMA.with_metadata({META_KEY: "{}"})) as w:
        w.write_table(pa.Table.from_pylist(rows, schema=SCHEMA))


def test_the_difference_is_paired_by_seed_over_the_seeds_both_have(tmp_path, capsys):
    _sweep(tmp_path / "a", {1: 0.30, 2: 0.50, 3: 0.40, 4: 9.0})
    _sweep(tmp_path / "b", {3: 0.38, 2: 0.47, 1: 0.28})  # seed 4 only in a: left out
    runpy.run_path(str(SCRIPT), run_name="not main")["main"](str(tmp_path / "a"), str(tmp_path / "b"))
    line = next(l for l in capsys.readouterr().out.splitlines() if l.split()[:2] == ["fatci", "mean"])
    d, h = mean_ci([0.02, 0.03, 0.02])
    assert line.split()[2] == "3"
    assert line.split()[-5:] == [f"{d:+.4f}", "±", f"{h:.4f}", "B", "lower"]
