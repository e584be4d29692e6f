"""001's fuzzy inference system (section 4.3): single input, single output, Mamdani.

Input sigma (the fitted standard deviation of a range, m) and output S (the factor of R,
eq. 31) each have three triangular sets, LE (less), EQ (equal), MO (more), given by their
peaks a < b < c::

    LE = tri(a, a, b),   EQ = tri(a, b, c),   MO = tri(b, c, c)

on the universe [a, c]; an input outside it is taken at its end. Rules (001): sigma LE ->
S LE, EQ -> EQ, MO -> MO. Inference: each rule's firing strength w_j = mu_j(sigma) clips
its output set (min), the clipped sets are joined (max), and S is the centroid ("gravity
method") of the joined area. The centroid integrates the piecewise-linear joined membership
over ``resolution`` points of the output universe exactly per segment, as scikit-fuzzy's
``defuzz(..., "centroid")`` does (the test compares the two).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def triangles(peaks: Sequence[float]) -> tuple[tuple[float, float, float], ...]:
    """(left foot, peak, right foot) of LE, EQ, MO from their peaks a < b < c."""
    a, b, c = (float(p) for p in peaks)
    if not a < b < c:
        raise ValueError(f"fuzzy set peaks {tuple(peaks)} must increase; give e.g. (0.1, 0.4, 0.7)")
    return (a, a, b), (a, b, c), (b, c, c)


def membership(x: np.ndarray, tri: tuple[float, float, float]) -> np.ndarray:
    """Triangular membership of x (a shoulder where a foot is the peak: 1 there)."""
    lo, peak, hi = tri
    up = (x - lo) / (peak - lo) if peak > lo else np.where(x >= peak, 1.0, 0.0)
    down = (hi - x) / (hi - peak) if hi > peak else np.where(x <= peak, 1.0, 0.0)
    return np.clip(np.minimum(up, down), 0.0, 1.0)


class FuzzySystem:
    """sigma -> S (module doc): ``inputs`` and ``outputs`` are the LE, EQ, MO peaks."""

    def __init__(self, inputs: Sequence[float], outputs: Sequence[float], resolution: int = 1001):
        self.inputs, self.outputs = triangles(inputs), triangles(outputs)
        self._lo, self._hi = self.inputs[0][0], self.inputs[2][2]
        self.universe = np.linspace(self.outputs[0][0], self.outputs[2][2], resolution)
        self._out = np.array([membership(self.universe, t) for t in self.outputs])  # (3, N)

    def __call__(self, sigma) -> np.ndarray:
        """S for each sigma (a scalar or an array: the same shape)."""
        x = np.clip(np.asarray(sigma, float), self._lo, self._hi)
        w = np.stack([membership(x, t) for t in self.inputs], axis=-1)  # (..., 3)
        mu = np.minimum(w[..., :, None], self._out).max(axis=-2)  # (..., N), joined
        s, h = self.universe, self.universe[1] - self.universe[0]
        m0, m1 = mu[..., :-1], mu[..., 1:]
        # each segment is a trapezoid: area h (m0 + m1)/2, first moment about 0 below
        area = 0.5 * h * (m0 + m1)
        moment = area * s[:-1] + h * h * (m0 + 2.0 * m1) / 6.0
        return moment.sum(axis=-1) / area.sum(axis=-1)
