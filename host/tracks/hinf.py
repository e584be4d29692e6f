"""``hinf``: 004's H-infinity filter (sect. 2, Theorem 2.3) on the relative error model of
host.tracks.relative: its gain comes from the LMI (2.15), min gamma (2.22-2.23), solved once
when the track starts (host.filters.hinf, cvxpy with Clarabel: the ``lmi`` extra).

The filter (2.9) is the predictor X_k+1 = A_f X_k + B_f Y_k with A_f = A - B_f C (2.25), C = I:
X_k+1 = A (X_k + A^-1 B_f (Y_k - X_k)), so its filtered estimate is X_k + K (Y_k - X_k) with
K = A^-1 B_f; closed around the strapdown (the prior is 0 after each feedback) every update
corrects the INS by K Y_k (host.tracks.relative). E of (2.3) is the sampling-time error
``sampling_error_ms`` along the velocity columns; B and D are the nominal noise's diagonal
(004 takes both as identities: docs/filters.md, "hinf").
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from navtwin.common.schema import key, non_negative
from navtwin.host.filters.hinf import solve_gain

from .relative import RelativeSettings, RelativeTrack, transition


@dataclass(frozen=True)
class HinfSettings(RelativeSettings):
    sampling_error_ms: float = key(1.0, "ms", "the sampling-time error delta t of 004 eq. 2.2 (E "
                                   "of eq. 2.3; 004's E matrices give 1.2 and 0.84 ms)",
                                   non_negative(hi=1000))


@lru_cache(maxsize=8)
def _gain(T: float, dt: float, process: tuple, measurement: tuple):
    """One LMI per set of settings, however many tracks use it."""
    return solve_gain(T, dt, np.array(process), np.array(measurement))


class HinfTrack(RelativeTrack):
    name = "hinf"
    Settings = HinfSettings
    requires = (("cvxpy", "lmi"), ("clarabel", "lmi"))

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        s = self.settings
        self.solution = _gain(self.T, s.sampling_error_ms * 1e-3, tuple(s.process.tolist()),
                              tuple(s.measurement.tolist()))
        self.K = np.linalg.solve(transition(self.T), self.solution.Bf)

    def gain(self, P_prior: np.ndarray) -> np.ndarray:
        return self.K
