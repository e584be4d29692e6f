"""LS-SVM regression (host/filters/lssvm.py, 004 section 3): the Cholesky/Schur solve against
a dense solve of the same KKT system (3.6), the KKT conditions, and 004's two-subset choice
of sigma and eta."""
from __future__ import annotations

import numpy as np
import pytest

from navtwin.host.filters.lssvm import PAPER_ETA, PAPER_GRID, PAPER_SIGMA, LsSvm, rbf, select


def errors(n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """INS-like inputs (3.10): position errors of tens of metres, velocity errors of a few m/s,
    and four smooth outputs (3.11) with noise."""
    X = np.column_stack([rng.uniform(-40, 40, (n, 2)), rng.uniform(-3, 3, (n, 2))])
    Y = np.column_stack([np.sin(X[:, 0] / 10) + 0.1 * X[:, 1], np.cos(X[:, 1] / 7),
                         0.2 * X[:, 2] ** 2, X[:, 3] - 0.05 * X[:, 0]])
    return X, Y + 0.05 * rng.standard_normal(Y.shape)


def dense(X, Y, sigma, eta, Xq):
    """(3.6) as one (N+1)-square system, solved by LU; the predictions (3.8) at Xq."""
    n = len(X)
    M = np.zeros((n + 1, n + 1))
    M[0, 1:] = M[1:, 0] = 1.0
    M[1:, 1:] = rbf(X, X, sigma) + np.eye(n) / eta
    sol = np.linalg.solve(M, np.vstack([np.zeros((1, Y.shape[1])), Y]))
    return rbf(Xq, X, sigma) @ sol[1:] + sol[0]


@pytest.mark.parametrize("sigma, eta", [(1, 1), (1, 1000), (30, 100), (100, 1000), (1000, 1000)])
def test_predictions_equal_a_dense_solve_of_the_kkt_system(sigma, eta):
    """To 1e-9 relative, sigma = eta = 1000 included (cond(K + I/eta) ~ 1e5: about 4e-12)."""
    rng = np.random.default_rng(4)
    X, Y = errors(100, rng)
    Xq, _ = errors(40, rng)
    got = LsSvm(sigma, eta).fit(X, Y).predict(Xq)
    want = dense(X, Y, sigma, eta, Xq)
    assert got.shape == (40, 4)
    assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()


def test_kkt_conditions_hold():
    """(3.6): sum alpha = 0, alpha_i = eta e_i with e_i = y_i - y(x_i)."""
    rng = np.random.default_rng(5)
    X, Y = errors(60, rng)
    m = LsSvm(30, 100).fit(X, Y)
    np.testing.assert_allclose(m.alpha.sum(axis=0), 0, atol=1e-9 * np.abs(m.alpha).max())
    np.testing.assert_allclose(m.alpha, m.eta * (Y - m.predict(X)), rtol=1e-7, atol=1e-9)


def test_one_output_and_one_query():
    rng = np.random.default_rng(6)
    X, Y = errors(30, rng)
    one = LsSvm(30, 100).fit(X, Y[:, 0])
    four = LsSvm(30, 100).fit(X, Y)
    np.testing.assert_allclose(one.predict(X[3])[:, 0], four.predict(X[3:4])[:, 0], rtol=1e-12)


def test_select_picks_the_known_best_and_trains_on_both_subsets():
    """sin(2x) from 100 noisy points: sigma = 1 follows it, sigma = 0.01 only memorises the
    validation points, sigma = 1000 is a low-order polynomial; the choice is then trained on
    all 100 points (004 section 5.2)."""
    rng = np.random.default_rng(7)
    x = rng.uniform(0, 10, (100, 1))
    y = np.sin(2 * x) + 0.05 * rng.standard_normal(x.shape)
    grid = ((1000, 1000), (0.01, 100), (1, 100))
    chosen = select(x, y, grid)
    assert list(chosen.scores) == list(grid)
    assert (chosen.model.sigma, chosen.model.eta) == (1, 100)
    assert min(chosen.scores.values()) == chosen.scores[(1, 100)] < 0.1
    assert len(chosen.model.X) == 100
    np.testing.assert_allclose(chosen.model.predict(x), LsSvm(1, 100).fit(x, y).predict(x))


def test_paper_grid_and_default():
    """004 Table 1's ten rows; its pick, sigma = eta = 1000, is the default."""
    assert len(PAPER_GRID) == 10 and PAPER_GRID[-1] == (PAPER_SIGMA, PAPER_ETA) == (1000, 1000)
    m = LsSvm()
    assert (m.sigma, m.eta) == (1000, 1000)
    rng = np.random.default_rng(8)
    X, Y = errors(100, rng)
    assert set(select(X, Y).scores) == set(PAPER_GRID)


def test_misuse_is_one_line():
    with pytest.raises(ValueError, match="sigma > 0"):
        LsSvm(0, 1)
    with pytest.raises(ValueError, match="before fit"):
        LsSvm().predict(np.zeros((1, 4)))


def test_standardise_is_the_fit_on_standardised_inputs():
    """standardise centres and scales each input by its training mean and deviation: the same
    model as a plain fit on inputs so transformed, and blind to the inputs' units."""
    rng = np.random.default_rng(8)
    X = rng.normal([3.0, -1.0, 0.0], [0.3, 2.0, 0.01], (60, 3))
    Y = np.column_stack([np.sin(X[:, 0] * 3), X[:, 1] ** 2, 50 * X[:, 2]])
    Xq = rng.normal([3.0, -1.0, 0.0], [0.3, 2.0, 0.01], (7, 3))
    mu, sd = X.mean(axis=0), X.std(axis=0)
    ours = LsSvm(1.5, 100.0, standardise=True).fit(X, Y).predict(Xq)
    plain = LsSvm(1.5, 100.0).fit((X - mu) / sd, Y).predict((Xq - mu) / sd)
    np.testing.assert_allclose(ours, plain, rtol=1e-12, atol=1e-12)
    units = np.array([1000.0, 0.01, 1e4])  # the same inputs in other units
    again = LsSvm(1.5, 100.0, standardise=True).fit(X * units, Y).predict(Xq * units)
    np.testing.assert_allclose(again, ours, rtol=1e-9, atol=1e-9)
    assert select(X, Y, standardise=True).model.standardise
