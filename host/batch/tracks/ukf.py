"""``ukf``'s twin (host.tracks.ukf): as the EKF's, the range measurements through each seed's
Merwe scaled sigma points and the acceleration in closed form (host.batch.ukf)."""
from __future__ import annotations

from navtwin.host.filters.model import DIM_X
from navtwin.host.filters.ukf import merwe_weights
from navtwin.host.tracks.ukf import UkfSettings

from ..ukf import unscented_correct
from .fusion import BatchTightTrack


class BatchUkfTrack(BatchTightTrack):
    name = "ukf"

    def __init__(self, ctx, settings=None) -> None:
        s = UkfSettings() if settings is None else settings
        super().__init__(ctx, s)
        self._weights = merwe_weights(DIM_X, s.alpha, s.beta, s.kappa)

    def correct(self, x, P, z, R, meas, gate):
        return unscented_correct(x, P, z, R, meas, gate, self._weights)
