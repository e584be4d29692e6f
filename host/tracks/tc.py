"""``tc``: 001's tightly coupled SINS/WSN filter (section 4.2, eqs. 17-24): the closed-loop
error state (host.tracks.errorstate) plus one NLOS random-walk state e_i per anchor
(eq. 17, e_i(k+1) = e_i(k) + w), updated with each range on its own (the Range product of
each exchange, corrected with c_i and f)::

    z = rho_INS,i - rho_WSN,i                                     (eq. 22)
    rho_INS,i = sqrt(|p - a_i|^2 + dz_i^2),  p the strapdown extrapolated to the exchange
    H = [u_i^T, lead u_i^T, 0 0 0, -1 at e_i],  u_i = (p - a_i) / rho_INS,i   (eqs. 23-24)
    R = range_variance(i, rho_WSN,i)   (range_sigma_m^2; fatci scales it)

One range is one scalar update, so a lone anchor still aids the track (no fix needed). The
e_i are estimates, not fed back: they stay in the filter, and a re-initialisation keeps
them.

A change from the paper. 001's eqs. 17, 18 and 21-24 write one NLOS error epsilon_d shared
by every anchor's range; an NLOS error belongs to an anchor's path (an obstacle between the
tag and that anchor), so by default each anchor has its own (``nlos_states = "per_anchor"``).
``nlos_states = "shared"`` is the paper's form: one state, -1 in every range's H.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import key, one_of, positive
from navtwin.host.filters.errorstate import NAV
from navtwin.host.measurements import Range

from .errorstate import ErrorStateSettings, ErrorStateTrack


@dataclass(frozen=True)
class TcSettings(ErrorStateSettings):
    nlos_sigma_m: float = key(0.5, "m", "initial NLOS error of each anchor's range, 1 sigma "
                              "(001 eq. 17's e_i)", positive(hi=100))
    nlos_walk_m_rt_s: float = key(0.05, "m/sqrt(s)", "random walk of each NLOS error (eq. 17's "
                                  "nabla_epsilon); uncalibrated, e_i also follows (f - 1) d",
                                  positive(hi=100))
    nlos_states: str = key("per_anchor", "", "NLOS random-walk states: per_anchor (one for "
                           "each anchor's path) or shared (001 eqs. 17-24: one for all)",
                           one_of("per_anchor", "shared"))


class TcTrack(ErrorStateTrack):
    name = "tc"
    Settings = TcSettings

    def __init__(self, ctx, settings=None) -> None:
        settings = settings or self.Settings()
        # one NLOS state per anchor, in the layout's order, or the paper's one for all
        self._shared = settings.nlos_states == "shared"
        self.extra = 1 if self._shared else len(ctx.layout.ids)
        super().__init__(ctx, settings)
        self._sigma2 = ctx.cfg.range_sigma_m**2

    def extra_psd(self) -> float:
        return self.settings.nlos_walk_m_rt_s**2

    def extra_p0(self) -> np.ndarray:
        return np.full(self.extra, self.settings.nlos_sigma_m**2)

    def handlers(self) -> dict:
        return {**super().handlers(), Range: self.range}

    def range_variance(self, row: int, distance: float) -> float:
        """R of one range of anchor ``row`` (layout order) measuring ``distance``."""
        return self._sigma2

    def variances(self, distances):
        """R of the ranges measuring *distances* (an array; host.batch's twin takes many)."""
        return np.full(np.shape(distances), self._sigma2)

    def range(self, m: Range) -> None:
        if not self.ready(m.t):
            return
        row = int(m.meas.idx[0])
        p, lead = self.position_at(m.t)
        r, u = self.ctx.layout.geometry(p, m.meas.idx)
        rho_wsn = float(m.z[0])
        H = np.zeros((1, NAV + self.extra))
        H[0, 0:2] = u[0]
        H[0, 2:4] = lead * u[0]
        H[0, NAV + (0 if self._shared else row)] = -1.0
        R = np.array([[self.range_variance(row, rho_wsn)]])
        self._update("range", m.t, np.array([r[0] - rho_wsn]), H, R, 1)
