"""Benchmarks (skipped by default): microseconds per filter step, strapdown step, estimator
IMU sample. Run: .venv/bin/python -m pytest tests/host/test_filters_bench.py --benchmark-only"""
import pytest

from navtwin.host.bench_filters import cases

CASES = cases()


@pytest.mark.parametrize("name", sorted(CASES))
def test_step(benchmark, name):
    benchmark(CASES[name])
