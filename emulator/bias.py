"""Slow bias processes of an inertial sensor: flicker (a flat Allan floor) and rate random walk.

Flicker bias. A first-order Gauss-Markov (GM) term of variance q and correlation time tau has
the Allan variance (x = T / tau; derivation in docs/emulator-models.md)::

    AVAR_GM(T) = q A(x),   A(x) = (2x - 3 + 4 e^-x - e^-2x) / x^2

rising as 2x/3 below tau and falling as 2/x above it. Terms with log-spaced correlation times
tau_k = tau_0 r^k and equal variances q add to a flat floor (the sum over k becomes an integral
over ln tau, int_0^inf A(x) dx / x = 2 ln 2)::

    AVAR(T) = q sum_k A(T / tau_k) ~ q (2 ln 2) / ln r,     so  q = floor^2 ln r / (2 ln 2)

which is the Allan variance of flicker noise, 2 ln 2 h_-1 for S(f) = h_-1 / f (IEEE 952:
S = B^2 / (2 pi f) gives the floor 0.664 B). Two terms a decade from 0.03 s to 30 000 s keep
the Allan deviation within 1.3 % of the floor from 1 s to 3000 s (0.04 % ripple inside).

Rate random walk: b_j = b_j-1 + K sqrt(Ts) w_j from 0; its Allan deviation is K sqrt(T / 3).

Each process draws from the Generator it is given (its sensor's own stream), all terms of a
block at once. The recursions run as a prefix scan in numpy (no scipy on the emulator's path
to its ready line): after the steps s = 1, 2, 4, ... each y_j holds
sum_{i=0}^{2s-1} phi^i x_{j-i}, every factor phi^s <= 1, so no step grows the rounding.
"""
from __future__ import annotations

import math

import numpy as np

#: correlation times of the flicker bias's Gauss-Markov terms: two a decade over 0.03 .. 30 000 s
FLICKER_TAUS_S = np.logspace(math.log10(0.03), math.log10(30_000.0), 13)
#: the band over which its Allan deviation is flat (within 1.3 %; tests/emulator/test_bias.py)
FLICKER_BAND_S = (1.0, 3000.0)


def gm_allan_variance(t: np.ndarray, tau: float, q: float = 1.0) -> np.ndarray:
    """Allan variance at averaging times *t* of a GM process of variance *q* and correlation
    time *tau*; the series 2x/3 - x^2/2 + 7x^3/30 below x = 0.05, where the closed form cancels."""
    x = np.asarray(t, dtype=float) / tau
    closed = (2 * x + 4 * np.expm1(-x) - np.expm1(-2 * x)) / np.maximum(x, 1e-300) ** 2
    return q * np.where(x < 0.05, 2 * x / 3 - x ** 2 / 2 + 7 * x ** 3 / 30, closed)


def flicker_term_variance(floor: float, taus: np.ndarray = FLICKER_TAUS_S) -> float:
    """q of each GM term for an Allan floor *floor* (the units of the sensor's output)."""
    return floor ** 2 * math.log(taus[1] / taus[0]) / (2 * math.log(2))


def flicker_allan_variance(t: np.ndarray, floor: float, taus: np.ndarray = FLICKER_TAUS_S) -> np.ndarray:
    """The exact Allan variance of the sum of GM terms :class:`FlickerBias` runs."""
    q = flicker_term_variance(floor, taus)
    return sum(gm_allan_variance(t, tau, q) for tau in taus)


class FlickerBias:
    """A 3-axis bias with a flat Allan floor *floor*: the GM terms of FLICKER_TAUS_S, each
    started stationary, sampled every *ts* seconds."""

    def __init__(self, floor: float, ts: float, rng: np.random.Generator) -> None:
        self.rng = rng
        sigma = math.sqrt(flicker_term_variance(floor))
        self.phi = np.exp(-ts / FLICKER_TAUS_S)
        self.drive = sigma * np.sqrt(1.0 - self.phi ** 2)
        self.state = sigma * rng.standard_normal((len(FLICKER_TAUS_S), 3))  # b_-1 of each term

    def next(self, n: int) -> np.ndarray:
        """The bias (n, 3) at the next *n* samples."""
        b = first_order(self.phi, self.drive[:, None, None] * self.rng.standard_normal((len(self.phi), n, 3)),
                        self.state)
        self.state = b[:, -1]
        return b.sum(axis=0)


def first_order(phi: np.ndarray, x: np.ndarray, before: np.ndarray) -> np.ndarray:
    """y_j = phi y_j-1 + x_j along axis 1 of *x* (K, n, 3), one phi per term k, from
    y_-1 = *before* (K, 3): a prefix scan of log2(n) numpy steps."""
    y = x.copy()
    scratch = np.empty_like(y)  # one buffer for every step's products, not one each
    step, power, n = 1, phi.copy(), y.shape[1]
    while step < n:
        product = np.multiply(power[:, None, None], y[:, :-step], out=scratch[:, :n - step])
        y[:, step:] += product
        step, power = 2 * step, power * power
    decay = phi[:, None] ** np.arange(1, y.shape[1] + 1)  # phi^(j+1)
    return y + decay[:, :, None] * before[:, None, :]


class RateRandomWalk:
    """A 3-axis bias random walk from 0: K sqrt(ts) per sample, K in output units per sqrt(s)."""

    def __init__(self, k: float, ts: float, rng: np.random.Generator) -> None:
        self.rng = rng
        self.step = k * math.sqrt(ts)
        self.state = np.zeros(3)

    def next(self, n: int) -> np.ndarray:
        b = self.state + self.step * np.cumsum(self.rng.standard_normal((n, 3)), axis=0)
        self.state = b[-1]
        return b
