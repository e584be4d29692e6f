"""The NLOS/multipath term eps of 001 eq. 13 for one anchor: slow in time, fixed in space.

eps_i(t, p) = g_i(p) + b_i(t), two independent zero-mean Gaussian parts
(docs/emulator-models.md section 6, ``[ranging.multipath]``):

* g_i, a stationary Gaussian field over the tag's (x, y) with the squared-exponential
  covariance field_sigma^2 exp(-|p - q|^2 / (2 L^2)), drawn once per scenario and seed as a
  sum of M random Fourier features (Rahimi & Recht 2007):
  g(p) = field_sigma sqrt(2 / M) sum_k cos(w_k . p + phi_k), w_k ~ N(0, I / L^2),
  phi_k ~ U(0, 2 pi). Cheap per exchange, and the same place gives the same error every
  lap, as a reflecting wall does.
* b_i, a first-order Gauss-Markov process (sd drift_sigma, correlation time tau) advanced
  exchange by exchange: b_k = a b_(k-1) + drift_sigma sqrt(1 - a^2) w_k, a = exp(-dt / tau),
  started from its stationary law; people and doors that move. A tau much longer than the
  run is 001's random walk (eq. 17).

Each part draws from its own stream (``nanoloc.anchor.<id>.field``, ``.drift``), one normal
per exchange for the drift, so the bytes do not depend on how time is sliced.
"""
from __future__ import annotations

import math

import numpy as np

from .rng import stream


class Multipath:
    """eps of one anchor; :meth:`error` is called with that anchor's exchanges in order."""

    def __init__(self, spec, anchor_id: int, seed: int) -> None:
        rng = stream(seed, f"nanoloc.anchor.{anchor_id}.field")
        m = spec.features
        self.w = rng.standard_normal((m, 2)) / spec.corr_length_m
        self.phi = rng.uniform(0.0, 2.0 * math.pi, m)
        self.amplitude = spec.field_sigma_m * math.sqrt(2.0 / m)
        self.drift_rng = stream(seed, f"nanoloc.anchor.{anchor_id}.drift")
        self.drift_sigma = spec.drift_sigma_m
        self.tau_ns = spec.drift_corr_s * 1e9
        self.b = None  # the drift at t_ns (None before the first exchange)
        self.t_ns = 0

    def field(self, xy: np.ndarray) -> np.ndarray:
        """g at the points *xy* (n, 2), metres."""
        return self.amplitude * np.cos(xy @ self.w.T + self.phi).sum(axis=1)

    def drift(self, t_ns: np.ndarray) -> np.ndarray:
        """b at the increasing times *t_ns* (this anchor's next exchanges)."""
        w = self.drift_rng.standard_normal(len(t_ns))
        out = np.empty(len(t_ns))
        for j, t in enumerate(t_ns.tolist()):
            if self.b is None:
                self.b = self.drift_sigma * w[j]
            else:
                a = math.exp(-(t - self.t_ns) / self.tau_ns)
                self.b = a * self.b + self.drift_sigma * math.sqrt(1.0 - a * a) * w[j]
            self.t_ns = t
            out[j] = self.b
        return out

    def error(self, t_ns: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """eps (m) of the exchanges starting at *t_ns* with the tag at *xy*."""
        return self.field(xy) + self.drift(t_ns)
