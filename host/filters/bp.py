"""004's back-propagation network: the baseline its LS-SVM beats during WSN outages (004
section 5.3, Table 3), trained on the same pairs (3.10 -> 3.11).

004 gives no architecture; this is a small standard one: one hidden layer of tanh units and a
linear output (default 4-10-4, the four INS errors in, the four corrections out)::

    h = tanh(W1' x + b1),   y = W2' h + b2

Inputs and outputs are standardised with the training set's mean and standard deviation
(a constant column is left unscaled). The weights start Glorot-uniform,
U(-sqrt(6 / (fan_in + fan_out)), +...), the biases at zero, from
``np.random.default_rng(seed)``, so the track's seed decides them and one seed gives
bit-identical predictions. Training is full-batch gradient descent with momentum on
E = 1/(2N) sum |y - t|^2 (standardised), back-propagated::

    d2 = (y - t) / N,          dW2 = H' d2,   db2 = 1'd2
    d1 = (d2 W2') * (1 - h^2), dW1 = X' d1,   db1 = 1'd1
    v = mu v - lr dW,  W = W + v      (each of W1, b1, W2, b2)

defaults ``EPOCHS`` = 500, ``LR`` = 0.05, ``MOMENTUM`` = 0.9 (all ours: 004 names none).
"""
from __future__ import annotations

import numpy as np

#: Defaults (004 names none): 4-10-4, 500 full-batch epochs, step 0.05, momentum 0.9.
HIDDEN, EPOCHS, LR, MOMENTUM = 10, 500, 0.05, 0.9


def _standardiser(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation per column (1 where a column is constant)."""
    sd = A.std(axis=0)
    return A.mean(axis=0), np.where(sd > 0, sd, 1.0)


def _glorot(rng: np.random.Generator, fan_in: int, fan_out: int) -> np.ndarray:
    return rng.uniform(-1.0, 1.0, (fan_in, fan_out)) * np.sqrt(6.0 / (fan_in + fan_out))


class BpNetwork:
    """One tanh hidden layer, linear output; :meth:`fit` by back-propagation, :meth:`predict`."""

    def __init__(self, n_in: int = 4, n_hidden: int = HIDDEN, n_out: int = 4, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.W1, self.b1 = _glorot(rng, n_in, n_hidden), np.zeros(n_hidden)
        self.W2, self.b2 = _glorot(rng, n_hidden, n_out), np.zeros(n_out)
        self.x_scale = self.y_scale = None
        self.losses: list[float] = []

    def _forward(self, Xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        H = np.tanh(Xs @ self.W1 + self.b1)
        return H, H @ self.W2 + self.b2

    def fit(self, X, Y, epochs: int = EPOCHS, lr: float = LR, momentum: float = MOMENTUM) -> BpNetwork:
        """Train on X (N x n_in), Y (N x n_out); :attr:`losses` holds E before each epoch."""
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.asarray(Y, float).reshape(len(X), -1)
        self.x_scale, self.y_scale = _standardiser(X), _standardiser(Y)
        Xs = (X - self.x_scale[0]) / self.x_scale[1]
        T = (Y - self.y_scale[0]) / self.y_scale[1]
        params = [self.W1, self.b1, self.W2, self.b2]
        velocity = [np.zeros_like(p) for p in params]
        n = len(X)
        self.losses = []
        for _ in range(epochs):
            H, out = self._forward(Xs)
            d2 = (out - T) / n
            self.losses.append(float(0.5 * np.sum((out - T) ** 2) / n))
            d1 = (d2 @ self.W2.T) * (1.0 - H * H)
            grads = [Xs.T @ d1, d1.sum(axis=0), H.T @ d2, d2.sum(axis=0)]
            for p, v, g in zip(params, velocity, grads):
                v *= momentum
                v -= lr * g
                p += v  # in place: params alias the weights
        return self

    def predict(self, Xq) -> np.ndarray:
        """The network's outputs for each row of Xq, in the training outputs' units."""
        if self.x_scale is None:
            raise ValueError("BP network predict before fit: train it on the WSN-present data first")
        Xs = (np.atleast_2d(np.asarray(Xq, float)) - self.x_scale[0]) / self.x_scale[1]
        return self._forward(Xs)[1] * self.y_scale[1] + self.y_scale[0]
