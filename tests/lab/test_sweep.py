"""Sweeps: the same cells on any number of workers, resumed, failures kept, the interval math."""
from __future__ import annotations

import gc
import json
import os
import re
import subprocess
import sys
import time

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy import stats

from navtwin.cli.main import main
from navtwin.emulator.scenario import load_scenario
from navtwin.lab import evaluate, sweep
from navtwin.protocols import __version__

from ..helpers import cli_error
from ..lines import Lines

#: Short runs: 5 s of office is two seeds a task (MIN_TASK_VIRTUAL_S), so chunks are exercised.
SHORT = 5.0


def test_two_workers_give_the_serial_table_bit_for_bit(tmp_path):
    serial = sweep.run("office", range(1, 5), duration=SHORT, serial=True, out=tmp_path / "serial")
    ours = os.environ.get("MALLOC_TRIM_THRESHOLD_")
    with sweep.Client(workers=2) as client:
        assert len(client.client.scheduler_info()["workers"]) == 2
        # glibc's malloc as in a plain process, not Dask's 64 kB trim (lab.sweep.worker_environ)
        assert set(client.client.run(os.getenv, "MALLOC_TRIM_THRESHOLD_").values()) == {ours}
        spread = sweep.run("office", range(1, 5), duration=SHORT, client=client,
                           out=tmp_path / "dask")
        # the default batch reckons with a worker's memory: a LocalCluster's share of it
        limits = {w["memory_limit"] for w in client.client.scheduler_info()["workers"].values()}
        assert sweep._workers(client) == (2, min(limits)) and min(limits) > 0
        # and our reckoning of the machine's memory is Dask's (within a page of rounding)
        assert sweep.worker_memory(None, 2) == pytest.approx(min(limits), abs=4096)
    assert serial.tasks == 1 and spread.tasks == 2  # one batch, or one per worker
    assert all(r["status"] == "ok" for r in serial.rows)
    assert spread.rows == serial.rows  # every cell, float for float
    assert sweep.table(sweep.summarise(spread.rows, spread.filters)) == \
        sweep.table(sweep.summarise(serial.rows, serial.filters))
    key = lambda r: (r["seed"], r["filter"])  # noqa: E731 - tasks finish in any order
    for result in (serial, spread):
        f = pq.ParquetFile(result.part)
        assert sorted(f.read().to_pylist(), key=key) == sorted(serial.rows, key=key)
        meta = json.loads(f.schema_arrow.metadata[sweep.META_KEY])
        assert meta["scenario_hash"] == sweep.scenario_hash(load_scenario("office"))
        assert meta["seeds"] == [1, 4] and meta["filters"] == list(serial.filters)
        assert meta["code_version"].startswith(__version__)


def test_the_engines_give_the_same_cells_and_table():
    """The batch engine's estimates equal the byte engine's to 1e-9 (tests/lab/test_batch.py),
    so do the cells made of them, and the table is the same to the digit."""
    filters = ("sins", "wsn", "kf", "ekf")
    runs = {e: sweep.run("office", range(1, 4), filters, duration=SHORT, serial=True, engine=e)
            for e in ("batch", "bytes")}
    batch_rows, byte_rows = runs["batch"].rows, runs["bytes"].rows
    assert [(r["seed"], r["filter"], r["status"]) for r in batch_rows] == \
        [(r["seed"], r["filter"], r["status"]) for r in byte_rows]
    for a, b in zip(batch_rows, byte_rows):
        for m in sweep.METRICS:
            assert a[m] == pytest.approx(b[m], rel=1e-9, abs=1e-12, nan_ok=True), (a["filter"], m)
    assert sweep.table(sweep.summarise(batch_rows, filters)) == \
        sweep.table(sweep.summarise(byte_rows, filters))


def test_a_batch_that_raises_is_run_seed_by_seed_by_the_byte_engine(monkeypatch):
    def broken(*args):
        raise FloatingPointError("a batch gone wrong")

    monkeypatch.setitem(sweep.ENGINES, "batch", broken)
    text = load_scenario("office").to_toml()
    rows = sweep.run_chunk(text, "office", [1, 2], ("sins", "kf"), SHORT, None, "batch")
    assert [(r["seed"], r["filter"], r["status"]) for r in rows] == [
        (1, "sins", "ok"), (1, "kf", "ok"), (2, "sins", "ok"), (2, "kf", "ok")]
    assert rows == sweep.run_chunk(text, "office", [1, 2], ("sins", "kf"), SHORT, None, "bytes")


def test_the_local_cluster_runs_no_work_for_a_client_without_its_credentials():
    """Another local user reached a sweep's LocalCluster on 127.0.0.1 and ran code as ours:
    now a plain client, one on TCP, and one with TLS credentials of its own are all refused,
    while the sweep runs on it."""
    from distributed import Client as DaskClient
    from distributed.security import Security

    with sweep.Client(workers=1) as client:
        info = client.client.scheduler_info()
        listening = [client.address, *info["workers"],
                     *(w["nanny"] for w in info["workers"].values())]
        assert all(a.startswith("tls://127.0.0.1:") for a in listening), listening
        port = client.address.rpartition(":")[2]
        for address, security in ((client.address, None), (f"tcp://127.0.0.1:{port}", None),
                                  (client.address, Security.temporary())):
            ran = False
            try:
                with DaskClient(address, security=security, timeout="5s") as intruder:
                    intruder.submit(print, "ran").result(timeout=5)
                    ran = True
            except Exception:  # refused; how depends on Dask: OSError, TypeError, or on a loaded
                pass  # box an AssertionError of its client's event loop (seen in CI)
            # a refused client is left half made in a reference cycle; its __del__ closes its
            # loop runner under a lock all of them share (distributed.utils.LoopRunner._lock),
            # so a collection that lands inside another client's start deadlocks (a 300 s
            # pytest-timeout in CI): collect it here, where no lock is held
            gc.collect()
            assert not ran, address
        result = sweep.run("office", [1], ("kf",), duration=2.0, client=client)
    assert [r["status"] for r in result.rows] == ["ok"]


def test_a_sweep_on_a_cluster_without_workers_ends_with_one_line(monkeypatch):
    """A cluster that cannot run the work ends the sweep with a SweepError, not a wait
    without end."""
    monkeypatch.setattr(sweep, "WATCH_S", 0.2)
    monkeypatch.setattr(sweep, "NO_WORKERS_S", 1.0)
    with sweep.Client(workers=1) as client:
        client.cluster.scale(0)
        deadline = time.monotonic() + 60
        while client.client.scheduler_info()["workers"]:
            assert time.monotonic() < deadline, "the worker did not stop"
            time.sleep(0.1)  # polling the scheduler: Dask has no wait for fewer workers
        with pytest.raises(sweep.SweepError, match=r"no workers for 1 s; start workers"):
            sweep.run("office", [1], ("kf",), duration=2.0, client=client)


def test_a_sweep_whose_scheduler_dies_ends_with_one_line(monkeypatch):
    monkeypatch.setattr(sweep, "WATCH_S", 0.2)
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler",
                                  "--host", "127.0.0.1", "--port", "0", "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        address = Lines(scheduler.stderr).search(r"Scheduler at:\s+(\S+)", "scheduler address",
                                                  timeout=60).group(1)
        with sweep.Client(address) as client:
            scheduler.kill()
            scheduler.wait(timeout=60)
            with pytest.raises(sweep.SweepError, match=r"lost during the sweep .*run the sweep "
                                                       r"again to finish it"):
                sweep.run("office", [1], ("kf",), duration=2.0, client=client)
    finally:
        scheduler.kill()
        scheduler.wait(timeout=60)


def _counting(monkeypatch, fail: set[int] = frozenset()) -> list[int]:
    """Record the seeds sweep.seed_cells (the byte engine's) is called with; raise for those
    in *fail*."""
    calls, real = [], sweep.seed_cells

    def seed_cells(sc, seed, filters, duration):
        calls.append(seed)
        if seed in fail:
            raise RuntimeError(f"boom on seed {seed}\nsecond line")
        return real(sc, seed, filters, duration)

    monkeypatch.setattr(sweep, "seed_cells", seed_cells)
    return calls


def test_a_rerun_computes_only_the_cells_it_lacks(tmp_path, monkeypatch):
    calls = _counting(monkeypatch)
    first = sweep.run("office", [1, 2], ("kf", "wsn"), duration=2.0, serial=True, out=tmp_path,
                      engine="bytes")
    assert first.tasks == 1 and calls == [1, 2]  # 2 s a seed: both in one task
    calls.clear()
    more = sweep.run("office", [1, 2, 3], ("kf", "wsn"), duration=2.0, serial=True, out=tmp_path,
                      engine="bytes")
    assert more.tasks == 1 and calls == [3]
    assert more.rows[:4] == first.rows
    calls.clear()
    again = sweep.run("office", [1, 2, 3], ("kf", "wsn"), duration=2.0, serial=True, out=tmp_path,
                      engine="bytes")
    assert again.tasks == 0 and calls == [] and again.part is None
    assert again.rows == more.rows
    assert more.rows == sweep.run("office", [1, 2, 3], ("kf", "wsn"), duration=2.0,
                                  serial=True).rows
    assert len(list(tmp_path.glob("part-*.parquet"))) == 2


def test_a_failing_cell_is_retried_once_then_kept_as_a_failed_row(tmp_path, monkeypatch):
    calls = _counting(monkeypatch, fail={2})
    result = sweep.run("office", [1, 2, 3], ("kf", "ekf"), duration=2.0, serial=True, out=tmp_path,
                       engine="bytes")
    assert calls == [1, 2, 2, 3]
    failed = [r for r in result.rows if r["status"] == "failed"]
    assert [(r["seed"], r["filter"]) for r in failed] == [(2, "kf"), (2, "ekf")]
    assert {r["error"] for r in failed} == {"RuntimeError: boom on seed 2"}
    assert all(r["mean"] is None for r in failed)
    s = sweep.summarise(result.rows, result.filters)["filters"]
    assert s["kf"]["seeds"] == 2 and s["kf"]["failed"] == 1
    stored = pq.read_table(result.part).to_pylist()
    assert sorted((r["seed"], r["filter"], r["status"]) for r in stored) == sorted(
        (r["seed"], r["filter"], r["status"]) for r in result.rows)
    monkeypatch.undo()  # the fault is gone: a re-run computes the failed seed
    calls = _counting(monkeypatch)
    healed = sweep.run("office", [1, 2, 3], ("kf", "ekf"), duration=2.0, serial=True, out=tmp_path,
                       engine="bytes")
    assert calls == [2] and all(r["status"] == "ok" for r in healed.rows)


def test_an_out_dir_of_another_sweep_is_refused(tmp_path, capsys):
    sweep.run("office", [1], ("kf",), duration=2.0, serial=True, out=tmp_path)
    with pytest.raises(sweep.SweepError, match="another duration"):
        sweep.run("office", [1], ("kf",), duration=3.0, serial=True, out=tmp_path)
    rc = main(["sweep", "--scenario", "corridor", "--seeds", "1", "--filters", "kf",
               "--duration", "2", "--serial", "--quiet", "--out", str(tmp_path)])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and f"--out {tmp_path}" in err[0] and "scenario hash" in err[0]


def test_the_cli_prints_json_and_writes_the_results_block(tmp_path, capsys):
    doc = tmp_path / "results.md"
    doc.write_text("# Results\n\nmine\n\n<!-- results:office -->\nold\n<!-- /results:office -->\n"
                   "\nafter\n")
    rc = main(["sweep", "--seeds", "1..2", "--filters", "kf,ekf", "--duration", "2",
               "--serial", "--quiet", "--json", "--out", str(tmp_path / "o"),
               "--results", str(doc)])
    assert rc == 0
    obj = json.loads(capsys.readouterr().out)
    assert obj["computed_tasks"] == 1 and set(obj["summary"]["filters"]) == {"kf", "ekf"}
    text = doc.read_text()
    assert text.startswith("# Results\n\nmine\n\n<!-- results:office -->\n"
                           "`office`, seeds 1..2, first 2 s")
    assert "\n| filter | seeds |" in text
    assert text.endswith("<!-- /results:office -->\n\nafter\n") and "old" not in text


def test_the_text_table_keeps_every_column_apart_however_wide_a_figure():
    """A NEES in the tens of thousands (a track far off its covariance) does not run into
    the RMSE before it: every row splits into the header's columns at two spaces."""
    rows = [{"scenario": "s", "seed": seed, "filter": f, "status": "ok", "error": "",
             **dict.fromkeys(sweep.METRICS, 1.0), "mean": m, "max": 2 * m, "rms": m,
             "nees_mean": 51831.6 + 2000 * seed}
            for seed in (1, 2) for f, m in (("sins", 737.8 + seed), ("centroid", 96.4))]
    text = sweep.table(sweep.summarise(rows, ("sins", "centroid")))
    table = [[c.strip() for c in re.split(r"\s{2,}", line.strip())]
             for line in text.split("\n\n")[0].splitlines()]
    assert table[0] == ["filter", "seeds", "failed", "mean m", "max m", "RMSE m", "NEES"]
    assert [len(r) for r in table[1:]] == [7, 7], text
    assert table[1][6].startswith("54831.600 ± 12706") and table[1][5].startswith("739.3"), text


def test_the_interval_is_students_t_on_the_per_seed_figures():
    v = np.random.default_rng(7).normal(0.3, 0.05, 17)
    m, h = sweep.mean_ci(v)
    lo, hi = stats.t.interval(0.95, len(v) - 1, loc=v.mean(), scale=stats.sem(v))
    assert m == pytest.approx(v.mean(), abs=1e-15)
    assert (m - h, m + h) == pytest.approx((lo, hi), rel=1e-12)
    assert np.isnan(sweep.mean_ci([1.0])[1])


def _rows(means: dict[str, list[float]]) -> list[dict]:
    return [sweep._row("x", seed, f, dict.fromkeys(sweep.METRICS, 1.0) | {"mean": m})
            for f, ms in means.items() for seed, m in enumerate(ms)]


def test_paired_differences_decide_a_ranking_only_where_the_interval_excludes_zero():
    rng = np.random.default_rng(3)
    base = rng.normal(0.5, 0.2, 30)  # a shared per-seed difficulty the pairing removes
    rows = _rows({"a": list(base), "b": list(base + 0.01 + rng.normal(0, 0.005, 30)),
                  "c": list(base + 0.01 + rng.normal(0, 0.5, 30))})
    s = sweep.summarise(rows, ("a", "b", "c"))
    pair = {(p["a"], p["b"]): p for p in s["pairs"]}
    d = base - np.array([r["mean"] for r in rows if r["filter"] == "b"])
    lo, hi = stats.t.interval(0.95, 29, loc=d.mean(), scale=stats.sem(d))
    ab = pair[("a", "b")]
    assert (ab["diff"] - ab["half"], ab["diff"] + ab["half"]) == pytest.approx((lo, hi))
    assert ab["better"] == "a" and hi < 0
    assert pair[("b", "c")]["better"] is None  # c's noise hides the same 0.01 m
    assert "a < b" in s["ranking"] and "~" in s["ranking"]


def test_the_markdown_puts_the_papers_figures_beside_ours():
    rows = _rows({"lc": [0.1, 0.2, 0.15], "tc": [0.09, 0.19, 0.14]})
    md = sweep.markdown(sweep.summarise(rows, ("lc", "tc")), "corridor")
    assert "| 001 mean m | 001 max m |" in md
    paper = evaluate.PAPER_FIGURES["corridor"]["figures"]
    assert f"| {paper['lc']['mean']:.4g} | {paper['lc']['max']:.4g} |" in md
    assert "| tc - lc |" not in md and "| lc - tc | 3 |" in md
    assert md.endswith("; 001's by its published means: `fatci < tc < lc`")


def test_corridor_markdown_has_001_table_1_in_its_layout_with_the_papers_figures():
    rng = np.random.default_rng(5)
    rows = [sweep._row("corridor", seed, f, {m: float(rng.random()) for m in sweep.METRICS})
            for f in ("lc", "tc", "fatci") for seed in range(6)]
    s = sweep.summarise(rows, ("lc", "tc", "fatci"))
    md = sweep.markdown(s, "corridor")
    paper = evaluate.PAPER_FIGURES["corridor"]["figures"]
    assert "| statistic | lc | tc | fatci |" in md
    row = next(line for line in md.splitlines() if line.startswith("| x error variance"))
    for f in ("lc", "tc", "fatci"):
        m, h = sweep.mean_ci([r["x_var"] for r in rows if r["filter"] == f])
        assert f"{m:.4f} ± {h:.4f} ({paper[f]['x_var']:.4g})" in row
    assert "Table 1" not in sweep.markdown(sweep.summarise(rows, ("lc",)), "office")


def test_an_out_that_holds_anything_but_parts_is_refused(tmp_path, capsys):
    rec = tmp_path / "recording"  # e.g. an emulator's recording directory
    rec.mkdir()
    (rec / "recording.json").write_text("{}")
    (rec / "sins.bin").write_bytes(b"\xaa" * 10)
    line = cli_error(capsys, "sweep", "--seeds", "1", "--filters", "kf", "--duration", "2",
                     "--serial", "--quiet", "--out", rec)
    assert f"--out {rec}: holds recording.json and 1 more" in line
    assert sorted(p.name for p in rec.iterdir()) == ["recording.json", "sins.bin"]
    assert (rec / "sins.bin").read_bytes() == b"\xaa" * 10


def test_a_results_file_that_cannot_be_written_is_refused_before_the_work(tmp_path, capsys,
                                                                         monkeypatch):
    calls = _counting(monkeypatch)
    out = tmp_path / "o"
    for results in (tmp_path, tmp_path / "nowhere" / "results.md"):
        line = cli_error(capsys, "sweep", "--seeds", "1", "--filters", "kf", "--duration", "2",
                         "--serial", "--quiet", "--out", out, "--results", results)
        assert f"--results {results}: " in line and "omit --results" in line
    assert calls == [] and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_results_on_a_read_only_file_system_is_refused_before_the_work(tmp_path):
    """The sweep ran to its end, then wrote --results into a read-only mount: a traceback.
    Here a read-only tmpfs in a user and mount namespace of its own (unshare -rm)."""
    ro, out = tmp_path / "ro", tmp_path / "o"
    ro.mkdir()
    probe = subprocess.run(["unshare", "-rm", "sh", "-c", f"mount -t tmpfs -o ro none {ro}"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"no read-only mount here: {probe.stderr.strip()}")
    script = (f"mount -t tmpfs -o ro none {ro} && exec {sys.executable} -m navtwin sweep "
              f"--seeds 1 --filters kf --duration 2 --serial --quiet --out {out} "
              f"--results {ro}/results.md")
    p = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 2 and p.stdout == "", p.stderr
    assert p.stderr.strip() == (f"navtwin sweep: error: --results {ro}/results.md: Read-only "
                                "file system; give a file you can write, or omit --results")
    assert not out.exists()  # refused before any cell was computed


def test_the_sweep_rate_benchmark_reads_its_workers_cpu_and_projects_the_goal():
    """lab-sweep's cluster figures come from the workers themselves (their user and system
    time), so a worker's time in the kernel is seen, and its projection is 10 000 seeds at
    the cluster's measured rate."""
    from navtwin.lab.bench import sweep_rate

    r = sweep_rate("office", seeds=2, workers=1, duration=2.0, filters=("kf",))
    assert r["same_cells"] and r["filters"] == ["kf"]
    assert r["workers_cpu_s_per_seed"] > 0 and 0 <= r["workers_system_share"] < 1
    minutes = 10_000 / r["cluster_seeds_per_s"] / 60
    assert r["minutes_for_10000_seeds"] == pytest.approx(minutes, rel=0.01)


def test_the_default_batch_fits_in_half_a_workers_memory():
    """BATCH_SIZE where a worker's memory holds it, fewer in proportion where it does not
    (longer scenarios hold more a seed), and never none."""
    per_seed = sweep.BATCH_BYTES_PER_SEED_S * 70.0  # a seed of office
    ample = 4 * sweep.BATCH_SIZE * per_seed
    assert sweep.batch_size_for(ample, 70.0) == sweep.BATCH_SIZE
    assert sweep.batch_size_for(200 * per_seed, 70.0) == 100  # half of it
    assert sweep.batch_size_for(200 * per_seed, 140.0) == 50
    assert sweep.batch_size_for(1.0, 70.0) == 1
    # serial, or a cluster still to be made: this machine's memory, shared by the workers
    assert sweep.worker_memory(None, 4) == pytest.approx(sweep.worker_memory(None, 1) / 4)


@pytest.mark.parametrize("n, workers, batch", [(10_000, 2, 256), (513, 2, 256), (4, 2, 256),
                                               (1, 2, 256), (300, 1, 256), (1000, 3, 64)])
def test_batch_tasks_share_the_seeds_evenly_among_the_workers(n, workers, batch):
    seeds = list(range(1, n + 1))
    tasks = sweep.chunk_seeds(seeds, 70.0, "batch", workers, batch)
    assert [s for t in tasks for s in t] == seeds
    sizes = [len(t) for t in tasks]
    assert max(sizes) <= batch
    assert max(sizes) - min(sizes) <= 1
    if n >= workers:  # a whole number of rounds of the workers
        assert len(tasks) % workers == 0
    if (n, workers, batch) == (10_000, 2, 256):
        assert sizes == [250] * 40
