"""004's back-propagation baseline (host/filters/bp.py): deterministic by seed, and it learns."""
from __future__ import annotations

import numpy as np
import pytest

from navtwin.host.filters.bp import BpNetwork


def smooth(n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Four INS-like errors in (metres, m/s) and four smooth corrections out."""
    X = np.column_stack([rng.uniform(-20, 20, (n, 2)), rng.uniform(-2, 2, (n, 2))])
    Y = np.column_stack([np.sin(X[:, 0] / 8), 0.05 * X[:, 1] * X[:, 2], np.tanh(X[:, 3]),
                         0.1 * X[:, 0] - 0.5 * X[:, 2]])
    return X, Y


def test_training_is_deterministic_by_seed():
    X, Y = smooth(100, np.random.default_rng(1))
    Xq, _ = smooth(20, np.random.default_rng(2))
    a = BpNetwork(seed=11).fit(X, Y, epochs=200).predict(Xq)
    b = BpNetwork(seed=11).fit(X, Y, epochs=200).predict(Xq)
    c = BpNetwork(seed=12).fit(X, Y, epochs=200).predict(Xq)
    assert np.array_equal(a, b)
    assert np.abs(a - c).max() > 1e-6


def test_it_learns_a_smooth_function():
    """Default 4-10-4, 500 epochs: on fresh points the error is a few % of the target's variance,
    and the loss fell."""
    X, Y = smooth(200, np.random.default_rng(3))
    Xq, Yq = smooth(200, np.random.default_rng(4))
    net = BpNetwork(seed=5).fit(X, Y)
    mse = np.mean((net.predict(Xq) - Yq) ** 2, axis=0)
    assert np.all(mse < 0.05 * Yq.var(axis=0)), mse / Yq.var(axis=0)
    assert net.losses[-1] < 0.1 * net.losses[0]


def test_predict_before_fit_is_one_line():
    with pytest.raises(ValueError, match="before fit"):
        BpNetwork().predict(np.zeros((1, 4)))
