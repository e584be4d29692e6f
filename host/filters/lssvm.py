"""LS-SVM regression (004 section 3): the model that bridges WSN outages.

Trained on pairs (x_k, y_k), k = 1..N, it is (3.8)::

    y(x) = sum_i alpha_i K(x, x_i) + b,   K(x, x_i) = exp(-|x - x_i|^2 / (2 sigma^2))   (3.9)

where alpha and b minimise 1/2 w'w + eta/2 sum e_k^2 subject to y_k = w'phi(x_k) + b + e_k
(3.2, 3.3); the KKT conditions (3.5, 3.6: alpha_i = eta e_i, sum alpha_i = 0) are the linear
system::

    [[0, 1'           ], [b    ]   [0]
     [1, K + I / eta  ]] [alpha] = [y]          K_kl = K(x_k, x_l)   (3.6, 3.7)

One kernel serves every output: Y is N x m, alpha N x m, b m (004's outputs are the four
corrections of (3.11) from the four INS errors of (3.10)).

**Solved by Cholesky and a Schur complement**, not by a dense solve of the (N+1)-square
matrix: H = K + I/eta is symmetric positive definite (K is a Gram matrix, 1/eta > 0), so with
H = R R' (one Cholesky) solve H nu = 1 and H mu = Y (two triangular solves per right-hand
side, all at once); then b = 1'mu / 1'nu (the Schur complement of H, -1'H^-1 1, is the
scalar b's equation) and alpha = mu - nu b. O(N^3 / 3) against the dense LU's O(2 N^3 / 3),
and no pivoting on the zero corner.

**Conditioning.** H's eigenvalues lie in [1/eta, N + 1/eta] (K's in [0, N]), so its
condition number is at most N eta + 1: 1e5 for 004's 100 points at eta = 1000, where the
solve keeps about 11 digits (tests/host/test_lssvm.py: the predictions of this solve and a
dense solve agree to 1e-9 relative, at sigma = 1000 too). At sigma = 1000 with metre-scale
inputs K is nearly constant (1 - K ~ 1e-4); the squared distances are taken as differences
(scipy's cdist), not as |x|^2 + |x_i|^2 - 2 x'x_i, so no offset of the inputs cancels and
no centring or scaling is needed for the solve. The *model* is another matter: so flat a kernel
makes the LS-SVM a heavily shrunk linear fit, which on outage-bridging explains under 2 % of
its targets' variance where a linear fit on the same inputs explains 20-70 %
(docs/results.md). With ``standardise`` each input is centred and scaled by its training
mean and standard deviation before the kernel (as host.filters.bp does), so sigma is in units
of the inputs' spread; 004 does not say what it did.

**Choosing sigma and eta** (:func:`select`, 004 section 3.1 after its ref. [22], and 5.2): the
training set's first half is the validation subset, the second the verification subset
(004: 100 points, 50 and 50); each (sigma, eta) of the grid is trained on the validation
subset and scored on the verification subset; the best is trained again on both. 004's
grid is its Table 1 (:data:`PAPER_GRID`); its Table 1 picked sigma = eta = 1000, the default
(:data:`PAPER_SIGMA`, :data:`PAPER_ETA`). 004 does not say how it ranks the rows (its "mean
error" columns are per quantity); the score here is the mean over the outputs of each
output's RMS error over its RMS on the verification subset, so metres and m/s weigh alike
(a deviation); ties go to the earlier row.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.spatial.distance import cdist

#: 004 Table 1's (sigma, eta) rows, in its order.
PAPER_GRID = ((1, 1), (1, 100), (1, 1000), (30, 100), (30, 1000), (50, 100), (50, 1000),
              (100, 100), (100, 1000), (1000, 1000))
#: 004 section 5.2's choice from Table 1: the track's default.
PAPER_SIGMA, PAPER_ETA = 1000.0, 1000.0


def rbf(A: np.ndarray, B: np.ndarray, sigma: float) -> np.ndarray:
    """K(a, b) = exp(-|a - b|^2 / (2 sigma^2)) for every row pair (3.9)."""
    return np.exp(-cdist(A, B, "sqeuclidean") / (2.0 * sigma * sigma))


class LsSvm:
    """LS-SVM regression with the RBF kernel: :meth:`fit` solves (3.6), :meth:`predict` is (3.8)."""

    def __init__(self, sigma: float = PAPER_SIGMA, eta: float = PAPER_ETA, standardise: bool = False):
        if not (sigma > 0 and eta > 0):
            raise ValueError(f"LS-SVM needs sigma > 0 and eta > 0, got sigma={sigma}, eta={eta}")
        self.sigma, self.eta, self.standardise = float(sigma), float(eta), bool(standardise)
        self.X = self.alpha = self.b = None
        self.centre, self.spread = 0.0, 1.0

    def _inputs(self, X) -> np.ndarray:
        return (np.atleast_2d(np.asarray(X, float)) - self.centre) / self.spread

    def fit(self, X, Y) -> LsSvm:
        """Train on inputs X (N x d) and outputs Y (N x m, or N for one output)."""
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.asarray(Y, float).reshape(len(X), -1)
        if self.standardise:  # a constant input stays 0 (spread 1)
            sd = X.std(axis=0)
            self.centre, self.spread = X.mean(axis=0), np.where(sd > 0.0, sd, 1.0)
            X = self._inputs(X)
        H = rbf(X, X, self.sigma)
        H[np.diag_indices_from(H)] += 1.0 / self.eta
        R = cho_factor(H, lower=True)
        sol = cho_solve(R, np.column_stack([np.ones(len(X)), Y]))
        nu, mu = sol[:, 0], sol[:, 1:]
        self.b = mu.sum(axis=0) / nu.sum()          # Schur complement: 1'H^-1(Y - 1 b) = 0
        self.alpha = mu - np.outer(nu, self.b)      # H alpha = Y - 1 b
        self.X = X
        return self

    def predict(self, Xq) -> np.ndarray:
        """y(x) for each row of Xq (q x d): q x m (3.8)."""
        if self.X is None:
            raise ValueError("LS-SVM predict before fit: train it on the WSN-present data first")
        return rbf(self._inputs(Xq), self.X, self.sigma) @ self.alpha + self.b


@dataclass(frozen=True)
class Selection:
    """The LS-SVM trained on the whole set with the chosen (sigma, eta), and every row's score."""
    model: LsSvm
    scores: dict


def score(model: LsSvm, X, Y) -> float:
    """Mean over the outputs of RMS(prediction - Y) / RMS(Y) on (X, Y)."""
    Y = np.asarray(Y, float).reshape(len(X), -1)
    error = model.predict(X) - Y
    return float(np.mean(np.sqrt(np.mean(error ** 2, axis=0) / np.mean(Y ** 2, axis=0))))


def select(X, Y, candidates=PAPER_GRID, standardise: bool = False) -> Selection:
    """004's simplified cross-validation: train each (sigma, eta) on the first half, score on
    the second, train the best on both (each model ``standardise``-d as given)."""
    X = np.atleast_2d(np.asarray(X, float))
    Y = np.asarray(Y, float).reshape(len(X), -1)
    half = len(X) // 2
    scores = {(s, e): score(LsSvm(s, e, standardise).fit(X[:half], Y[:half]), X[half:], Y[half:])
              for s, e in candidates}
    sigma, eta = min(scores, key=scores.get)  # the first of equal scores
    return Selection(LsSvm(sigma, eta, standardise).fit(X, Y), scores)
