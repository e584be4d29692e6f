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

Each term is stepped every m_k samples, m_k = max(1, floor(tau_k / (HOLD_RATIO ts))), as a GM
process on that grid (phi = exp(-m_k ts / tau_k)), and held in between: the slow terms draw
once in many samples (0.5 normals a sample per axis at 819.2 Hz, not 13). Averaged over the
phase of the grid, which an overlapping Allan estimate does, a held term's autocovariance is
the chord of q e^(-|t|/tau) between the grid's lags, so its Allan curve is the GM's to the
chord's error. At HOLD_RATIO = 8 and 819.2 samples/s the samples' exact curve
(:func:`flicker_allan_variance` with *ts*) is the continuous terms' within 0.8 % at 10 ms
and 0.1 % from 0.1 s to 3000 s (tests/emulator/test_bias.py; docs/emulator-models.md 3.1).

Rate random walk: b_j = b_j-1 + K sqrt(Ts) w_j from 0; its Allan deviation is K sqrt(T / 3).

Each process draws from the Generator it is given (its sensor's own stream), all steps of a
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
#: a term is held for at most tau_k / HOLD_RATIO between its steps (module doc)
HOLD_RATIO = 8


def hold_samples(ts: float, taus: np.ndarray = FLICKER_TAUS_S) -> np.ndarray:
    """m_k: the samples each term is held for at sample period *ts* (at least one)."""
    return np.maximum(1, np.floor(taus / (HOLD_RATIO * ts))).astype(np.int64)


def gm_allan_variance(t: np.ndarray, tau: float, q: float = 1.0) -> np.ndarray:
    """Allan variance at averaging times *t* of a GM process of variance *q* and correlation
    time *tau*; the series 2x/3 - x^2/2 + 7x^3/30 below x = 0.05, where the closed form cancels."""
    x = np.asarray(t, dtype=float) / tau
    closed = (2 * x + 4 * np.expm1(-x) - np.expm1(-2 * x)) / np.maximum(x, 1e-300) ** 2
    return q * np.where(x < 0.05, 2 * x / 3 - x ** 2 / 2 + 7 * x ** 3 / 30, closed)


def flicker_term_variance(floor: float, taus: np.ndarray = FLICKER_TAUS_S) -> float:
    """q of each GM term for an Allan floor *floor* (the units of the sensor's output)."""
    return floor ** 2 * math.log(taus[1] / taus[0]) / (2 * math.log(2))


def flicker_allan_variance(t: np.ndarray, floor: float, ts: float | None = None,
                           taus: np.ndarray = FLICKER_TAUS_S) -> np.ndarray:
    """The Allan variance of the sum of GM terms at averaging times *t*: of the continuous
    terms (*ts* None, the design), or exactly of the samples :class:`FlickerBias` makes at
    period *ts* (*t* rounded to whole samples), averaged over the phase of the holds."""
    q = flicker_term_variance(floor, taus)
    if ts is None:
        return sum(gm_allan_variance(t, tau, q) for tau in taus)
    n = np.maximum(1, np.rint(np.asarray(t, dtype=float) / ts))
    return q * sum(_held_allan_variance(n, int(m), math.exp(-m * ts / tau))
                   for m, tau in zip(hold_samples(ts, taus), taus))


def _held_allan_variance(n: np.ndarray, m: int, phi: float) -> np.ndarray:
    """AVAR / q at n samples of one held term: its phase-averaged autocorrelation at lag
    l = a m + b is r(l) = phi^a (1 - b (1 - phi) / m). With y the difference of two n-sample
    means, AVAR = (1 / 2n^2) sum_l c(l) (r(0) - r(l)) over the lags' weights
    c(l) = 2n - 3l (l <= n), l - 2n (n < l <= 2n), whose sum over l = 1 .. 2n is -n:

        AVAR = (n + S) / n^2,   S = sum_{l=1}^{2n} (2n - 3l) r(l) + 4 sum_{l=n+1}^{2n} (l - n) r(l)

    S in closed form from the prefix sums F_p(L) = sum_{l<L} l^p r(l), block by block. On the
    grids :func:`hold_samples` gives, m ts >= tau / 16, so 1 - phi > 0.06 and the geometric
    sums do not cancel (a term of phi near 1 would need their expm1 forms)."""
    beta = (1.0 - phi) / m

    def prefix(big_l):  # F_0 and F_1 over l < big_l: K whole blocks and B lags of the next
        k, b = np.divmod(big_l, m)
        geo = (1.0 - phi ** k) / (1.0 - phi)  # sum_{a<K} phi^a
        ageo = phi * (1.0 - k * phi ** (k - 1) + (k - 1) * phi ** k) / (1.0 - phi) ** 2  # sum a phi^a
        a0 = m - beta * m * (m - 1) / 2  # sum_b (1 - beta b) over a whole block
        a1 = m * (m - 1) / 2 - beta * (m - 1) * m * (2 * m - 1) / 6  # sum_b b (1 - beta b)
        p0 = b - beta * b * (b - 1) / 2
        p1 = b * (b - 1) / 2 - beta * (b - 1) * b * (2 * b - 1) / 6
        f0 = a0 * geo + phi ** k * p0
        f1 = m * a0 * ageo + a1 * geo + phi ** k * (k * m * p0 + p1)
        return f0, f1

    f0_all, f1_all = prefix(2 * n + 1)
    f0_half, f1_half = prefix(n + 1)
    s = 2 * n * (f0_all - 1.0) - 3 * f1_all + 4 * ((f1_all - f1_half) - n * (f0_all - f0_half))
    return (n + s) / n ** 2


class FlickerBias:
    """A 3-axis bias with a flat Allan floor *floor*: the GM terms of FLICKER_TAUS_S, each
    started stationary and stepped every :func:`hold_samples` samples of period *ts*, the
    first step at the first sample (module doc)."""

    def __init__(self, floor: float, ts: float, rng: np.random.Generator) -> None:
        self.rng = rng
        sigma = math.sqrt(flicker_term_variance(floor))
        self.hold = hold_samples(ts)
        self.phi = np.exp(-self.hold * ts / FLICKER_TAUS_S)
        self.drive = sigma * np.sqrt(1.0 - self.phi ** 2)
        self.state = sigma * rng.standard_normal((len(FLICKER_TAUS_S), 3))  # each term before its first step
        self.samples = 0  # made so far

    def next(self, n: int) -> np.ndarray:
        """The bias (n, 3) at the next *n* samples (:meth:`together`, alone)."""
        return FlickerBias.together([self], n)[0]

    @staticmethod
    def together(biases: list[FlickerBias], n: int) -> np.ndarray:
        """The biases (S, n, 3) of S alike processes (one floor and period: a sweep's seeds)
        at their next *n* samples, each seed's numbers what it would make alone: the terms'
        sum before the block, plus each step's change at its sample, summed down the block.
        Each seed draws from its own stream, term by term. Each term that steps is scanned
        over its own steps, its S seeds at once: the fastest steps 273 times in 819 samples at
        819.2 Hz, most once or not at all, so one scan of all, each padded to the most steps,
        did five times the arithmetic (the padding's values unused, the steps' the same)."""
        first_bias = biases[0]
        hold, j0 = first_bias.hold, first_bias.samples
        for b in biases:
            b.samples = j0 + n
        first = -(-j0 // hold) * hold - j0  # each term's first step in the block (may be >= n)
        steps = np.maximum(0, -(-(n - first) // hold))
        state = np.stack([b.state for b in biases])  # (S, terms, 3)
        change = np.zeros((n, len(biases), 3))  # samples first: each step's slice contiguous
        change[0] = state.sum(axis=1)
        draws = np.empty((len(biases), steps.sum(), 3))
        for b, row in zip(biases, draws):
            b.rng.standard_normal(out=row)
        end = np.cumsum(steps)
        for k in np.flatnonzero(steps):
            x = first_bias.drive[k] * draws[:, end[k] - steps[k]:end[k]].swapaxes(0, 1)
            before = state[:, k]
            b = first_order(first_bias.phi[k], x, before)
            change[first[k]::hold[k]] += np.diff(b, axis=0, prepend=before[None])
            state[:, k] = b[-1]
        for bias, s in zip(biases, state):
            bias.state = s
        return np.cumsum(change, axis=0).swapaxes(0, 1)


def first_order(phi: float, x: np.ndarray, before: np.ndarray) -> np.ndarray:
    """y_j = phi y_j-1 + x_j along axis 0 of *x* (n, S, 3), from y_-1 = *before* (S, 3): phi
    y_-1 joins x_0, then a prefix scan of log2(n) numpy steps."""
    y = np.array(x, order="C")  # each step's slices contiguous: several times faster than seeds first
    y[0] += phi * before
    scratch = np.empty_like(y)  # one buffer for every step's products, not one each
    step, power, n = 1, phi, len(y)
    while step < n:
        y[step:] += np.multiply(power, y[:-step], out=scratch[:n - step])
        step, power = 2 * step, power * power
    return y


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

    @staticmethod
    def together(walks: list[RateRandomWalk], n: int) -> np.ndarray:
        """The next *n* samples (S, n, 3) of S walks, each as alone."""
        return np.stack([w.next(n) for w in walks])
