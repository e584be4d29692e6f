"""Filters stepped for N seeds at once along a leading seed axis (issue 23, the batch engine's
numeric core): one float64 numpy implementation of the same products as host.filters.

A batch filter holds x (N, n) and P (N, n, n); each step takes per-seed inputs along the
same axis and an ``active`` mask (a seed left out keeps its x and P). Every product is
``np.matmul`` on stacked operands of the per-filter shapes (a vector as an (n, 1) column):
numpy hands each seed's slice to the same BLAS routine (gemm, gemv, dot) that the
per-filter ``ndarray.dot`` calls, in the same order, so each seed's x and P equal the
per-filter path's bit for bit (tests/host/test_batch.py asserts it, and 1e-12 beside
filterpy). The per-step cost is numpy's per-call overhead divided by N, plus about 35 ns
per 6x6 product per seed (``navtwin bench batch``).

base.py: BatchFilter (x, P, the active seeds of a step, the update); seeds.py: inputs per
seed or shared, dt grouped by value; linalg.py: the stacked inverse and products;
innovation.py: the gated Joseph update (BatchInnovation); kf.py: BatchKalmanFilter (host.filters.kf); errorstate.py:
BatchErrorStateFilter (host.filters.errorstate); model.py: the measurement models (a fix's
lag, the ranges and their differences with each seed's lags: host.filters.model); ukf.py: the
UKF's sigma-point update (host.filters.ukf); bench.py: ``navtwin bench batch``.
"""
from .errorstate import BatchErrorStateFilter
from .innovation import BatchInnovation
from .kf import BatchKalmanFilter

__all__ = ["BatchErrorStateFilter", "BatchInnovation", "BatchKalmanFilter"]
