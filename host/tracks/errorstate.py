"""What 001's tracks (lc, tc, fatci) share: a closed-loop error-state filter
(host.filters.errorstate) on a strapdown of their own. Its gating, late measurements,
feedback and discontinuities (:class:`ClosedLoopTrack`) 003's geodetic tracks share too
(host.tracks.geodetic).

Strapdown. The estimator's strapdown (``ctx.sins``) is the pure SINS, which the sins track
reports and the CA tracks measure; an error-state track corrects its strapdown after every
update, so it runs a copy: taken when the alignment ends, then stepped with every IMU sample
the estimator accepts (the same samples, the same integration) and predicted at the IMU
rate (001 eq. 27) with that step's specific force.

Time. The strapdown's time is its last IMU sample's. A measurement at t is compared with
the strapdown extrapolated over t - t_nav (tens of ms either way) at its velocity, so its
H has the velocity columns (t - t_nav) H_p; one older than ``max_lag_s`` is ``late``.

Gating, discontinuities: as the CA tracks (host.tracks.fusion, docs/filters.md): updates
gated at ``gate_probability``; every position update gated out for ``gate_reopen_s``, a
device restart or an IMU gap make the track start again at the next WSN fix newer than it
(the fix's position and covariance, at rest with ``reinit_sigma`` on velocity, the attitude
kept); after an IMU restart it starts again from the realigned strapdown.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import key, positive
from navtwin.host.filters.errorstate import NAV, ErrorStateFilter
from navtwin.host.measurements import ImuSample
from navtwin.host.measurements import Fix
from navtwin.host.wsn import chi2_gate

from .base import OwnStrapdown, Track, estimate


@dataclass(frozen=True)
class ErrorStateSettings:
    """The error-state tracks' process noise (001 eq. 4: W = [gyro noise, accel noise]) and
    initial attitude uncertainty. The defaults are 3x the ADIS16350's random walks (4.2
    deg/sqrt(h), 2.0 m/s/sqrt(h)): what the
    alignment leaves of the gyro bias, and the accelerometer bias that a turn shows, act on
    the filter like extra white noise (docs/filters.md)."""

    gyro_noise_deg_rt_hr: float = key(12.6, "deg/sqrt(h)", "attitude error random walk "
                                      "(001 eq. 4, omega_epsilon)", positive(hi=1e5))
    accel_noise_m_s_rt_hr: float = key(6.0, "m/s/sqrt(h)", "velocity error random walk "
                                       "(001 eq. 4, delta a^b)", positive(hi=1e5))
    attitude_sigma_deg: float = key(0.5, "deg", "initial attitude error, 1 sigma per axis",
                                    positive(hi=180))


class ClosedLoopTrack(Track):
    """What every closed-loop error-state track shares (001's here, 003's in
    host.tracks.geodetic): its strapdown ``nav`` at ``t_nav`` and its ``filter``; when a
    measurement is late; the gated update, the feedback it gives (:meth:`feed_back`) and
    when gating turns the track off; the discontinuities of a restart or a gap. A subclass
    gives :meth:`_reset` (a fresh filter at its strapdown) and :meth:`feed_back`."""

    uses_strapdown = True

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        self.nav = None  # the track's strapdown
        self.filter = None
        self.t_nav: float | None = None
        self._aided: float | None = None
        self._gated_since: float | None = None

    def _reset(self) -> None:
        raise NotImplementedError

    def feed_back(self) -> None:
        """Move the filter's estimated errors into the strapdown (and zero them in x)."""
        raise NotImplementedError

    def restart(self, device: str, t: float) -> None:
        self.discontinuity("restart", t)
        if device == "imu":
            self.nav = self.filter = None  # a new alignment gives the attitude

    def gap(self, t: float) -> None:
        self.discontinuity("gap", t)

    # -- updates ----------------------------------------------------------------------------
    def ready(self, t: float) -> bool:
        """Whether a measurement at t can update the track (else counted ``late``)."""
        if self.nav is None or self.pending:
            return False
        if self.t_nav - t > self.ctx.cfg.max_lag_s:
            self.rejections["late"] += 1
            return False
        return True

    def _update(self, kind: str, t: float, z, H, R, dof: int) -> bool:
        """One gated update and its feedback into the strapdown; counts the outcome."""
        cfg = self.ctx.cfg
        try:
            inn = self.filter.update(z, H, R, chi2_gate(dof, cfg.gate_probability))
        except np.linalg.LinAlgError:
            self._reset()
            return False
        if not inn.accepted:
            self.rejections["gate"] += 1
            if self._gated_since is None:
                self._gated_since = t
            elif t - self._gated_since > cfg.gate_reopen_s:
                self.discontinuity("gated", t)  # every update gated out so long: the track is off
            return False
        self.feed_back()
        self._gated_since = None
        self._aided = t
        self.updates[kind] += 1
        return True


class ErrorStateTrack(OwnStrapdown, ClosedLoopTrack):
    Settings = ErrorStateSettings
    extra = 0  # random-walk states after the nav part

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        s = self.settings
        self._gyro_psd = (math.radians(s.gyro_noise_deg_rt_hr) / 60.0) ** 2
        self._accel_psd = (s.accel_noise_m_s_rt_hr / 60.0) ** 2

    def extra_psd(self) -> float:
        return 0.0

    def extra_p0(self) -> np.ndarray:
        return np.zeros(0)

    def handlers(self) -> dict:
        return {ImuSample: self.imu}

    # -- life -------------------------------------------------------------------------------
    def _new_filter(self, p_var: np.ndarray, v_var: float) -> None:
        """A filter with position covariance p_var and velocity variance v_var; the attitude
        and random-walk states of the previous filter, if any, go on."""
        n = NAV + self.extra
        P0 = np.zeros((n, n))
        P0[:2, :2] = p_var
        P0[2, 2] = P0[3, 3] = v_var
        old = self.filter
        if old is None:
            P0[4, 4] = P0[5, 5] = P0[6, 6] = math.radians(self.settings.attitude_sigma_deg) ** 2
            k = np.arange(NAV, n)
            P0[k, k] = self.extra_p0()
        else:
            P0[4:, 4:] = old.P[4:, 4:]
        self.filter = ErrorStateFilter(P0, gyro_psd=self._gyro_psd, accel_psd=self._accel_psd,
                                       extra=self.extra, extra_psd=self.extra_psd())
        if old is not None:
            self.filter.x[NAV:] = old.x[NAV:]
        self._gated_since = None

    def started(self, t: float) -> None:
        self._reset()

    def stepped(self, t: float, dt: float) -> None:
        if dt > 0.0:
            self.filter.predict(dt, self.nav.f_n)

    def _reset(self) -> None:
        """A fresh filter at the strapdown, P0 from ``p0_sigma`` and ``attitude_sigma_deg``
        (at the start; or after a covariance lost positive definiteness: never seen, rounding
        could do it)."""
        if self.filter is not None:
            self.rejections["numerical_reset"] += 1
        self.filter = None
        sp, sv, _ = self.ctx.cfg.p0_sigma
        self._new_filter(sp**2 * np.eye(2), sv**2)

    def reinit_at(self, fix: Fix) -> bool:
        """Start again at ``fix``, at rest with ``reinit_sigma`` on velocity, the attitude
        kept; before the strapdown realigned after an IMU restart, wait for it."""
        if self.nav is None:
            return False
        sv, _ = self.ctx.cfg.reinit_sigma
        self.nav.place(fix.p, (0.0, 0.0))
        self._new_filter(fix.cov, sv**2)
        self._aided = fix.t
        return True

    # -- updates ----------------------------------------------------------------------------
    def position_at(self, t: float) -> tuple[np.ndarray, float]:
        """The strapdown's horizontal position extrapolated to t, and t - t_nav."""
        lead = t - self.t_nav
        return self.nav.p[:2] + lead * self.nav.v[:2], lead

    def feed_back(self) -> None:
        dx = self.filter.take_nav()
        self.nav.correct(dx[0:2], dx[2:4], dx[4:7])

    # -- output -----------------------------------------------------------------------------
    def estimate(self, b: float, yaw: float):
        ctx = self.ctx
        if self.nav is None:
            return self.unstarted(b, yaw)
        lead = b - self.t_nav
        p, v = self.nav.p[:2] + lead * self.nav.v[:2], self.nav.v[:2]
        F = np.eye(4)
        F[0, 2] = F[1, 3] = lead
        cov = F.dot(self.filter.P[:4, :4]).dot(F.T)
        stale = self.pending or ctx.stale(b, self._aided)
        return estimate(b, self.name, p, v, self.nav.yaw, cov, stale)
