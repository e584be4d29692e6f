"""``ukf``: UKF, tightly coupled (host.filters.ukf): as the EKF, the range measurements
through Merwe scaled sigma points (``[filters.ukf] alpha, beta, kappa``, beside the EKF's
``tight``)."""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import between, key
from navtwin.host.filters import UnscentedKalmanFilter

from .fusion import TightSettings, TightTrack


@dataclass(frozen=True)
class UkfSettings(TightSettings):
    alpha: float = key(1.0, "", "sigma-point spread", between(1e-4, 1))
    beta: float = key(2.0, "", "prior knowledge of the distribution (2: Gaussian)", between(0, 10))
    # n + kappa > 0 for the UKF's n = 6; 3 - n = -3 is the usual
    kappa: float | None = key(None, "", "secondary scaling; none: 3 - n", between(-3, 10))


class UkfTrack(TightTrack):
    name = "ukf"
    Settings = UkfSettings

    def make_filter(self, x0, P0):
        s = self.settings
        return UnscentedKalmanFilter(x0, P0, self.ctx.model, s.alpha, s.beta, s.kappa)
