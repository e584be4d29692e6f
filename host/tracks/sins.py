"""``sins``: the pure strapdown track (host.sins): coarse alignment on the stationary start,
then mechanization at the IMU rate (000 eqs. 1-5). The estimator runs the strapdown (the
fusion tracks use it too); this track reports it.

Covariance: the initial one (``p0_sigma``) plus the growth that the accelerometer's
velocity random walk alone causes (a lower bound: tilt and heading errors add to it).
Extrapolated: no IMU sample for ``extrapolated_after_s``.
"""
from __future__ import annotations

from dataclasses import dataclass

from navtwin.common.schema import key, positive
from navtwin.host.imu_noise import VRW_M_S_RT_HR

from .base import Track, estimate


@dataclass(frozen=True)
class SinsSettings:
    vrw_m_s_rt_hr: float = key(VRW_M_S_RT_HR, "m/s/sqrt(h)", "accelerometer velocity random walk "
                               "of the ADIS16350's 10 ms reads: the track's covariance", positive(hi=1000))


class SinsTrack(Track):
    name = "sins"
    Settings = SinsSettings
    uses_strapdown = True
    aided = False

    def restart(self, device: str, t: float) -> None:
        if device == "imu":
            self.count_reinit("restart")

    def gap(self, t: float) -> None:
        if self.ctx.sins is not None:  # dead reckoning over an unknown stretch
            self.count_reinit("gap")

    def estimate(self, b: float, yaw: float):
        ctx = self.ctx
        sp, sv, _ = ctx.cfg.p0_sigma
        pp, pv, vv = float(sp) ** 2, 0.0, float(sv) ** 2
        sins = ctx.sins
        if sins is None:
            p, v = ctx.origin, (0.0, 0.0)
        else:
            dt = b - ctx.t_imu
            v = sins.v[:2]
            p = sins.p[:2] + v * dt
            # velocity random walk q per axis: P_pp = q T^3/3, P_pv = q T^2/2, P_vv = q T
            T = b - ctx.t_aligned
            q = (self.settings.vrw_m_s_rt_hr / 60.0) ** 2
            pp, pv, vv = pp + q * (T**3 / 3), pv + q * (T**2 / 2), vv + q * T
        cov = [pp, 0.0, pv, 0.0, 0.0, pp, 0.0, pv, pv, 0.0, vv, 0.0, 0.0, pv, 0.0, vv]  # (x, y) alike
        return estimate(b, self.name, p, v, yaw, cov, ctx.stale(b, ctx.t_imu))
