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

Sets from the calibration (``sets_from = "calibration"``, :func:`calibrated_sets`): the input
peaks follow the lab's own sigma(d) over the distances it was calibrated at (the span), so
that the fuzzy system spans the ranges the lab sees::

    LE, MO = min, max of sigma(d) over the span      (its ends, sigma(d) rising)
    EQ = median of sigma(d) over the span            (its middle, sigma(d) monotonic)
    R_0 = EQ^2                                       (range_sigma_m := EQ)

so a range at the span's middle gets R_0 (S(EQ) = 1 with the default output sets) and the
ends sigma^2 as with the defaults below. Without a calibration the settings' sets and
range_sigma_m stand, as sigma_poly_m stands for sigma(d).

Defaults: input peaks 0.1, 0.4, 0.7 m (0.4 = range_sigma_m's default); output peaks 0.05,
0.7, 2.25, whose sets' centroids are 0.27, 1.0 and 1.73: with b = 2 a range of sigma 0.1,
0.4 or 0.7 m gets R = sigma^2 (0.107^2, 0.4^2, 0.69^2 m^2), and in between the fuzzy
system's plateau around EQ. sigma_poly_m = (0.3, 0.02): the emulator's office ranging
(sigma0_m + sigma_per_m d, docs/emulator-models.md); the corridor config has its calibration
(sets_from = "calibration").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import Check, between, each, key, one_of, positive
from navtwin.host.filters.fuzzy import FuzzySystem

from .tc import TcSettings, TcTrack

_TABLE_POINTS = 601  # S^b tabulated over the input universe: a range costs an interpolation
_SPAN_POINTS = 601  # sigma(d) sampled over the calibrated span (odd: the median is the middle)


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
    sets_from: str = key("settings", "", "input sets and R_0: settings (sigma_sets_m, "
                         "range_sigma_m) or calibration (from its sigma(d) where the host has "
                         "one, else the settings: docs/filters.md)",
                         one_of("settings", "calibration"))

    def check_config(self, cfg) -> None:
        """What spans sections: sets from a calibration need its sigma(d) not flat."""
        if self.sets_from == "calibration" and cfg.calibration is not None:
            calibrated_sets(cfg.calibration)


def calibrated_sets(calibration) -> tuple[float, float, float]:
    """LE, EQ, MO input peaks (m) from a calibration's sigma(d) (module docstring): min,
    median and max of sigma(d) over its calibrated span; EQ is also R_0's sigma."""
    sigma = calibration.sigma(np.linspace(*calibration.sigma_span_m, _SPAN_POINTS))
    peaks = (float(sigma.min()), float(np.median(sigma)), float(sigma.max()))
    if not peaks[0] < peaks[1] < peaks[2]:
        where = calibration.source or "the calibration"
        raise ValueError(f"fatci sets_from = 'calibration': the sigma(d) of {where} gives peaks "
                         f"{peaks}, not increasing (a flat curve); set [filters.fatci] sets_from "
                         "= 'settings' and give sigma_sets_m")
    return peaks


class FatciTrack(TcTrack):
    name = "fatci"
    Settings = FatciSettings

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        s = self.settings
        calibration = ctx.calibration
        peaks = s.sigma_sets_m
        if s.sets_from == "calibration" and calibration is not None:  # else the settings'
            peaks = calibrated_sets(calibration)
            self._sigma2 = peaks[1] ** 2
        fis = FuzzySystem(peaks, s.s_sets)
        self._grid = np.linspace(peaks[0], peaks[2], _TABLE_POINTS)
        self._table = fis(self._grid) ** s.b * self._sigma2
        self.sigma = calibration.sigma if calibration is not None else np.polynomial.Polynomial(s.sigma_poly_m)

    def range_variance(self, row: int, distance: float) -> float:
        return float(self.variances(float(distance)))

    def variances(self, distances):
        return np.interp(self.sigma(distances), self._grid, self._table)
