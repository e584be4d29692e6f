"""``fatci``: 001's fuzzy adaptive tightly coupled filter (section 4.3, Algorithm 1): tc with
each range's R set by the fuzzy system (host.filters.fuzzy) from that range's standard
deviation::

    sigma_W = sigma(rho_WSN)            the fitted sigma(d) at the measured distance
    S = FIS(sigma_W)                    LE/EQ/MO triangles, centroid (Algorithm 1, line 7)
    R = S^b R_0,  R_0 = range_sigma_m^2 (eq. 31, line 8)

Eq. 31 is written R_{k+1} = S^b R_k; applied recursively it would shrink or grow R without
bound whenever S != 1, so R_k is read as the nominal R_0 of every range. sigma(d) is the
calibration's fitted curve (``ctx.calibration.sigma``, from ``navtwin calibrate``) when the
host has one, else the polynomial ``sigma_poly_m`` of these settings.

Defaults: input peaks 0.1, 0.4, 0.7 m (0.4 = range_sigma_m's default); output peaks 0.05,
0.7, 2.25, whose sets' centroids are 0.27, 1.0 and 1.73: with b = 2 a range of sigma 0.1,
0.4 or 0.7 m gets R = sigma^2 (0.107^2, 0.4^2, 0.69^2 m^2), and in between the fuzzy
system's plateau around EQ. sigma_poly_m = (0.3, 0.02): the emulator's office ranging
(sigma0_m + sigma_per_m d, docs/emulator-models.md); the corridor config sets its own.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import Check, between, each, key, positive
from navtwin.host.filters.fuzzy import FuzzySystem

from .tc import TcSettings, TcTrack

_TABLE_POINTS = 601  # S^b tabulated over the input universe: a range costs an interpolation


def _increasing() -> Check:
    return Check(lambda v: len(v) == 3 and v[0] < v[1] < v[2], "must be three increasing peaks "
                 "(LE, EQ, MO)", "give e.g. [0.1, 0.4, 0.7]")


@dataclass(frozen=True)
class FatciSettings(TcSettings):
    sigma_sets_m: tuple[float, float, float] = key((0.1, 0.4, 0.7), "m", "peaks of the input sets "
                                                   "LE, EQ, MO (001 Fig. 7a)", each(positive(hi=100)),
                                                   _increasing())
    s_sets: tuple[float, float, float] = key((0.05, 0.7, 2.25), "", "peaks of the output sets LE, "
                                             "EQ, MO (001 Fig. 7b)", each(positive(hi=1e4)),
                                             _increasing())
    b: float = key(2.0, "", "exponent of S in R = S^b R_0 (001 eq. 31)", between(0, 10))
    sigma_poly_m: tuple[float, ...] = key((0.3, 0.02), "m, m/m, ...", "sigma(d) = sum c_k d^k "
                                          "without a calibration (ascending powers)",
                                          each(between(-100, 100)),
                                          Check(lambda v: len(v) >= 1, "needs a coefficient",
                                                "give e.g. [0.3, 0.02]"))


class FatciTrack(TcTrack):
    name = "fatci"
    Settings = FatciSettings

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        s = self.settings
        fis = FuzzySystem(s.sigma_sets_m, s.s_sets)
        self._grid = np.linspace(s.sigma_sets_m[0], s.sigma_sets_m[2], _TABLE_POINTS)
        self._table = fis(self._grid) ** s.b * self._sigma2
        calibration = ctx.calibration
        self.sigma = calibration.sigma if calibration is not None else np.polynomial.Polynomial(s.sigma_poly_m)

    def range_variance(self, row: int, distance: float) -> float:
        return float(np.interp(float(self.sigma(distance)), self._grid, self._table))
