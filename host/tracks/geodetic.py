"""What 003's tracks share (``geosins``, ``centroid``, ``wcl``): the geodetic strapdown
(host.geodetic) and its 16-state error-state filter (host.filters.geodetic), closed loop
(host.tracks.errorstate.ClosedLoopTrack: gating, late measurements, discontinuities), and
``geosins``, that strapdown free (003 Table 1's "Single SINS").

Frames. The strapdown holds latitude, longitude, height and ENU velocity; the track's
estimates stay in the area frame every consumer reads: the local tangent plane at the site
(common.geodesy.LocalFrame of ``[site] latitude_deg, longitude_deg``, ``[filters]
altitude_m`` and ``x_azimuth_deg``), x, y of the strapdown's position converted exactly
(through ECEF), velocity and yaw rotated from ENU by the area's azimuth. A position error
(dL, dlambda) is (R_N + h) cos L dlambda east and (R_M + h) dL north; these ENU axes at the
vehicle are those of the site's plane to 2.5e-4 rad at 1.5 km (left out).

Start (``start_from``):

* ``alignment`` (000's and 001's way): when the estimator's stationary alignment ends, at
  its strapdown's position, velocity, attitude and gyro bias;
* ``configured`` (003 sect. 4.1's way: the vehicle moves from its first sample): at the
  first IMU sample, at the vehicle's ``start`` at rest, with ``roll_deg``, ``pitch_deg`` and
  the vehicle's ``heading_deg``; the configured values are the host's knowledge, the initial
  errors 003 sets are in them (host/configs/rssi-centroid.toml).

P0: ``p0_sigma``'s position and velocity sigmas (horizontal and vertical alike),
``height_sigma_m``, ``tilt_sigma_deg`` on phi_E, phi_N, ``heading_sigma_deg`` on phi_U,
``accel_bias_ug`` and ``gyro_drift_deg_h`` on the bias states. Q_c: ``gyro_arw_deg_rt_hr``,
``accel_vrw_m_s_rt_hr`` and the bias random walks (host.filters.geodetic).

Covariance of an estimate: J P J^T, J the (x, y, vx, vy) rows of the map above, with the
extrapolation to the output instant.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navtwin.common.geodesy import LocalFrame
from navtwin.common.schema import between, key, one_of, positive
from navtwin.host.filters.geodetic import (ACCEL_BIAS, GYRO_DRIFT, MAG, NAV, PHI, POS, V, GeodeticErrorFilter,
                                           error_model)
from navtwin.host.geodetic import GeodeticStrapdown
from navtwin.host.measurements import Fix, ImuSample
from navtwin.host.sins import area_from_enu, quat_from_euler
from navtwin.protocols.adis16350 import (ARW_DEG_RT_HR, GYRO_BIAS_INSTABILITY_DPS, STANDARD_GRAVITY,
                                        VRW_M_S_RT_HR)

from .base import estimate
from .errorstate import ClosedLoopTrack

MICRO_G = STANDARD_GRAVITY * 1e-6  # m/s^2


@dataclass(frozen=True)
class GeodeticSettings:
    """The geodetic strapdown's start and its filter's noise. The defaults are the ADIS16350's
    (datasheet ARW, VRW and bias stability; random walks of the bias stability over 100 s);
    003's grade is host/configs/rssi-centroid.toml's."""

    start_from: str = key("alignment", "", "where the strapdown starts: the estimator's "
                          "alignment, or the configured start, attitude and heading at the "
                          "first IMU sample (003 sect. 4.1)", one_of("alignment", "configured"))
    roll_deg: float = key(0.0, "deg", "initial roll with start_from = configured", between(-90, 90))
    pitch_deg: float = key(0.0, "deg", "initial pitch with start_from = configured", between(-90, 90))
    gyro_arw_deg_rt_hr: float = key(ARW_DEG_RT_HR, "deg/sqrt(h)", "gyro angle random walk (Q_c on "
                                    "phi)", positive(hi=1e5))
    accel_vrw_m_s_rt_hr: float = key(VRW_M_S_RT_HR, "m/s/sqrt(h)", "accelerometer velocity random "
                                     "walk (Q_c on dV)", positive(hi=1e5))
    gyro_drift_deg_h: float = key(GYRO_BIAS_INSTABILITY_DPS * 3600, "deg/h", "gyro drift, 1 sigma "
                                  "per axis at the start (003 eq. 16's eps)", positive(hi=1e6))
    gyro_drift_rw_deg_h_rt_h: float = key(458.0, "deg/h/sqrt(h)", "gyro drift random walk",
                                          between(0, 1e6))
    accel_bias_ug: float = key(700.0, "ug", "accelerometer bias, 1 sigma per axis at the start "
                               "(003 eq. 16's nabla)", positive(hi=1e6))
    accel_bias_rw_ug_rt_h: float = key(594.0, "ug/sqrt(h)", "accelerometer bias random walk",
                                       between(0, 1e6))
    tilt_sigma_deg: float = key(0.5, "deg", "initial roll and pitch error, 1 sigma (phi_E, phi_N)",
                                positive(hi=180))
    heading_sigma_deg: float = key(0.5, "deg", "initial heading error, 1 sigma (phi_U)",
                                   positive(hi=180))
    height_sigma_m: float = key(1.0, "m", "initial height error, 1 sigma", positive(hi=1e4))


class GeodeticTrack(ClosedLoopTrack):
    """The geodetic strapdown and its filter (module docstring); aided subclasses call
    :meth:`_update` with an H over the 16 states."""

    Settings = GeodeticSettings

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        cfg, s = ctx.cfg, self.settings
        self.frame = LocalFrame(cfg.latitude_deg, cfg.longitude_deg, cfg.altitude_m, cfg.x_azimuth_deg)
        self._area = area_from_enu(cfg.x_azimuth_deg)[:2, :2]  # ENU east, north -> area x, y
        self._yaw_offset = math.radians(cfg.x_azimuth_deg - 90.0)  # area yaw = ENU yaw + this
        psd = np.zeros(16)
        psd[V] = (s.accel_vrw_m_s_rt_hr / 60.0) ** 2
        psd[PHI] = (math.radians(s.gyro_arw_deg_rt_hr) / 60.0) ** 2
        psd[ACCEL_BIAS] = (s.accel_bias_rw_ug_rt_h * MICRO_G / 60.0) ** 2
        psd[GYRO_DRIFT] = (math.radians(s.gyro_drift_rw_deg_h_rt_h) / 3600.0 / 60.0) ** 2
        psd[MAG] = self.magnetometer_psd()
        self._psd = psd

    def magnetometer_psd(self) -> float:
        """Q_c of the magnetometer heading's error (an aided track with the magnetometer)."""
        return 0.0

    def magnetometer_p0(self) -> float:
        return 0.0

    def handlers(self) -> dict:
        return {ImuSample: self.imu}

    # -- the area frame -----------------------------------------------------------------------
    def position_map(self) -> np.ndarray:
        """d(x, y)/d(dL, dlambda) at the strapdown's position (2 x 2)."""
        rm, rn = self.nav.radii()
        return self._area @ np.array([[0.0, rn * math.cos(self.nav.lat)], [rm, 0.0]])

    def area_position(self) -> np.ndarray:
        nav = self.nav
        return self.frame.local(math.degrees(nav.lat), math.degrees(nav.lon), nav.h)[:2]

    def area_velocity(self) -> np.ndarray:
        return self._area @ np.asarray(self.nav.v[:2])

    def area_yaw(self) -> float:
        yaw = self.nav.euler[2] + self._yaw_offset
        return math.atan2(math.sin(yaw), math.cos(yaw))

    def position_at(self, t: float) -> tuple[np.ndarray, float]:
        """The strapdown's area position extrapolated to t, and t - t_nav."""
        lead = t - self.t_nav
        return self.area_position() + lead * self.area_velocity(), lead

    def position_rows(self, lead: float) -> np.ndarray:
        """H of the area position extrapolated by *lead* (2 x 16)."""
        H = np.zeros((2, 16))
        H[:, 6:8] = self.position_map()
        H[:, 0:2] = lead * self._area
        return H

    # -- life -----------------------------------------------------------------------------------
    def imu(self, rec: ImuSample) -> None:
        if self.nav is None and not self._start(rec):
            return
        dt = rec.t - self.t_nav
        nav = self.nav
        nav.step(dt, tuple(map(float, rec.gyro)), tuple(map(float, rec.accel)))
        self.t_nav = rec.t
        if dt > 0.0:
            self.filter.predict(dt, error_model(nav.lat, nav.radii(), nav.v, nav.f_n, nav.dcm()))

    def _start(self, rec: ImuSample) -> bool:
        """Start the strapdown (``start_from``) at this sample; False: not yet."""
        cfg, s = self.ctx.cfg, self.settings
        if s.start_from == "configured":
            p, v = self.ctx.origin, (0.0, 0.0, 0.0)
            roll, pitch, yaw = math.radians(s.roll_deg), math.radians(s.pitch_deg), cfg.heading_rad
            bias = (0.0, 0.0, 0.0)
        else:
            sins = self.ctx.sins
            if sins is None:  # aligning
                return False
            p, v = sins.p[:2], (*(self._area.T @ sins.v[:2]), 0.0)
            (roll, pitch, yaw), bias = sins.euler, sins.gyro_bias
        lat, lon, h = self.frame.geodetic((p[0], p[1], 0.0))
        self.nav = GeodeticStrapdown(latitude_rad=math.radians(float(lat)),
                                     longitude_rad=math.radians(float(lon)), height_m=float(h), velocity=v,
                                     q=quat_from_euler(roll, pitch, yaw - self._yaw_offset),
                                     local_gravity=cfg.local_gravity, gyro_bias=bias)
        self.filter = None
        self._reset()
        self.t_nav = rec.t
        self.reinit_since = None
        return True

    def _reset(self) -> None:
        """A fresh filter at the strapdown, P0 of the module docstring."""
        if self.filter is not None:
            self.rejections["numerical_reset"] += 1
        cfg, s = self.ctx.cfg, self.settings
        sp, sv, _ = cfg.p0_sigma
        rm, rn = self.nav.radii()
        sd = np.zeros(16)
        sd[V] = sv
        sd[PHI] = (math.radians(s.tilt_sigma_deg),) * 2 + (math.radians(s.heading_sigma_deg),)
        sd[POS] = (sp / rm, sp / (rn * math.cos(self.nav.lat)), s.height_sigma_m)
        sd[ACCEL_BIAS] = s.accel_bias_ug * MICRO_G
        sd[GYRO_DRIFT] = math.radians(s.gyro_drift_deg_h) / 3600.0
        sd[MAG] = self.magnetometer_p0()
        self.filter = GeodeticErrorFilter(np.diag(sd**2), self._psd)
        self._gated_since = None

    def reinit_at(self, fix: Fix) -> bool:
        """Start again at ``fix``, at rest with ``reinit_sigma`` on velocity; the attitude, the
        biases and their covariance kept; before the strapdown restarted, wait for it."""
        if self.nav is None:
            return False
        sv, _ = self.ctx.cfg.reinit_sigma
        lat, lon, _ = self.frame.geodetic((fix.p[0], fix.p[1], 0.0))
        self.nav.place(math.radians(float(lat)), math.radians(float(lon)))
        M = np.linalg.inv(self.position_map())
        P = self.filter.P
        for k in (V, POS):
            P[k, :] = 0.0
            P[:, k] = 0.0
        P[0:3, 0:3] = sv**2 * np.eye(3)
        P[6:8, 6:8] = M @ np.asarray(fix.cov, float) @ M.T
        P[8, 8] = self.settings.height_sigma_m**2
        self.filter.x[:NAV] = 0.0
        self._gated_since = None
        self._aided = fix.t
        return True

    def feed_back(self) -> None:
        dx = self.filter.take_nav()
        self.nav.correct(dx[V], dx[PHI], dx[POS], dx[ACCEL_BIAS], dx[GYRO_DRIFT])

    # -- output ---------------------------------------------------------------------------------
    def estimate(self, b: float, yaw: float):
        ctx = self.ctx
        if self.nav is None:
            return self.unstarted(b, yaw)
        p, lead = self.position_at(b)
        J = np.zeros((4, 16))
        J[0:2] = self.position_rows(lead)
        J[2:4, 0:2] = self._area
        cov = J @ self.filter.P @ J.T
        return estimate(b, self.name, p, self.area_velocity(), self.area_yaw(), cov, self.stale(b))

    def stale(self, b: float) -> bool:
        return self.pending or self.ctx.stale(b, self._aided)


class GeoSinsTrack(GeodeticTrack):
    """``geosins``: the geodetic strapdown free (003 Table 1's "Single SINS"); its covariance
    the filter's predict alone. A restart or a gap is counted; after an IMU restart the
    strapdown starts again (``start_from``); a gap is integrated over (dead reckoning)."""

    name = "geosins"
    aided = False

    def restart(self, device: str, t: float) -> None:
        self.count_reinit("restart")
        if device == "imu":
            self.nav = self.filter = None

    def gap(self, t: float) -> None:
        if self.nav is not None:
            self.count_reinit("gap")

    def stale(self, b: float) -> bool:
        return self.ctx.stale(b, self.t_nav)
