"""The estimator's inertial part: the IMU stream from its samples to the strapdown and the
Motion product (docs/filters.md).

* Checks. A sample with a non-finite value is implausible; one with the data-ready flag
  down repeats a register read (the next sample covers the interval); one not after the
  previous sample is out of order: the strapdown needs its samples strictly in order.
* Alignment. The vehicle stands still for ``alignment_s`` from the board's power-up (its
  sample counter gives ``uptime_s``; else from the first sample): the samples are averaged
  (host.sins.Alignment), then the strapdown starts at ``origin`` with the alignment's
  attitude and gyro bias, and steps with every later sample (000 eqs. 1-5).
* Motion. Each sample's product for the fusion tracks: at rest while aligning (velocity and
  acceleration zero, ``stationary_sigma``), then the strapdown's nav-frame acceleration with
  sigma^2 = accel_sigma_m_s2^2 + (tilt_inflation g s T)^2 (s the tilt rate the alignment
  leaves, T the time since it).
* Gaps and restarts. A lost sample or more is bridged up to ``imu_gap_s``; beyond, the
  integration restarts at the next sample. An IMU restart realigns: a new alignment from
  the power-up, the strapdown starting at the mean of the fixes since the restart.
"""
from __future__ import annotations

import math
from collections import Counter

import numpy as np

from navtwin.protocols import sins as sins_format

from .filters import ACCELERATION, Linear
from .measurements import ImuSample, Motion
from .sins import Alignment, AlignmentResult, Strapdown

#: At rest: velocity and acceleration are zero (used while the alignment runs).
STATIONARY = Linear(np.hstack([np.zeros((4, 2)), np.eye(4)]))


class Inertial:
    """Turns IMU samples into the strapdown's state and Motion products.

    Owns the alignment (``alignment``, its result ``aligned``, the time it ended
    ``t_aligned``), the strapdown (``sins``, None until aligned), the latest sample's time
    (``t_imu``), the power-up time the alignment counts from, the strapdown's start
    (``origin``: the configured start, after an IMU restart the mean of the fixes since),
    and the IMU stream's counts: ``counts`` (samples, overrange, gaps_bridged, gaps_reinit)
    and ``rejections`` (by reason)."""

    def __init__(self, cfg, need_sins: bool) -> None:
        self.cfg = cfg
        self.need_sins = need_sins  # some track uses the strapdown: align, then run it
        self.alignment = Alignment()
        self.aligned: AlignmentResult | None = None
        self.sins: Strapdown | None = None
        self.t_imu: float | None = None
        self.t_aligned: float | None = None
        self._t_first: float | None = None  # the alignment counts from here (the power-up)
        self.sample: tuple[tuple, tuple] | None = None  # the accepted sample's (gyro, accel)
        self._last_sample: tuple[tuple, tuple] | None = None  # the alignment's last one
        self.origin = tuple(cfg.start)  # where the strapdown starts when its alignment ends
        self._origin_since: float | None = None  # after an IMU restart: the fixes from then on,
        self._origin_fixes = (np.zeros(2), 0)  # summed and counted, give it (at rest: their mean)
        self._tilt_growth = (cfg.tilt_inflation * cfg.local_gravity * cfg.tilt_rate_sigma) ** 2
        self._accel_var = cfg.accel_sigma_m_s2**2
        sv, sa = cfg.stationary_sigma
        self._r_stationary = np.diag([sv**2, sv**2, sa**2, sa**2])
        self._at_rest = np.zeros(4)
        self._i2 = np.eye(2)
        self._gyro_limit = math.radians(cfg.gyro_range_dps)
        self.counts: Counter = Counter()
        self.rejections: Counter = Counter()

    def accept(self, rec: ImuSample) -> bool:
        """Whether the sample is taken (else counted by reason); taken, its (gyro, accel) as
        plain floats are ``sample`` (the strapdown's arithmetic is faster on them than on
        small arrays), for :meth:`step`."""
        self.counts["samples"] += 1
        t_s = rec.t
        gyro = tuple(map(float, rec.gyro))
        accel = tuple(map(float, rec.accel))
        if not (math.isfinite(t_s) and all(map(math.isfinite, gyro)) and all(map(math.isfinite, accel))):
            self.rejections["imu_implausible"] += 1
            return False
        if rec.uptime_s is not None and self._t_first is None:  # even on a stale sample
            self._t_first = self._power_up(t_s, rec.uptime_s)
        if not rec.nd_ok:  # a repeated register read: the next sample covers the interval
            self.rejections["imu_stale"] += 1
            return False
        if self.t_imu is not None and t_s <= self.t_imu:
            self.rejections["imu_out_of_order"] += 1
            return False
        if max(map(abs, gyro)) >= self._gyro_limit:
            self.counts["overrange"] += 1  # saturated, still the best reading there is
        self.sample = gyro, accel
        return True

    def _power_up(self, t_s: float, uptime_s: float) -> float | None:
        """When the board that has been up *uptime_s* at t_s powered up, if that is within
        the alignment (the vehicle stands still from then): the alignment counts from there.
        None: it is over (or the counter wrapped), the alignment counts from the next sample."""
        return t_s - uptime_s if 0.0 <= uptime_s < self.cfg.alignment_s else None

    def gap(self, t_s: float) -> bool:
        """Whether samples were lost before t_s (a link fade, a pulled cable) for longer than
        ``imu_gap_s``: then what happened in the gap is unknown, the integration restarts at
        this sample and the tracks that depend on it start again (counted ``gaps_reinit``).
        A shorter gap the strapdown bridges with this sample (``gaps_bridged``)."""
        if self.t_imu is None or t_s - self.t_imu <= 1.5 * sins_format.PERIOD_S:
            return False
        if t_s - self.t_imu <= self.cfg.imu_gap_s:
            self.counts["gaps_bridged"] += 1
            return False
        self.counts["gaps_reinit"] += 1
        if self.sins is not None:
            self.t_imu = t_s  # the next step integrates from here, over nothing
        return True

    def gaps(self) -> dict:
        """IMU gaps so far: ``bridged`` (the state kept) and ``reinit`` (the tracks restarted)."""
        return {"bridged": self.counts["gaps_bridged"], "reinit": self.counts["gaps_reinit"]}

    def step(self, t: float) -> tuple | None:
        """Advance alignment or strapdown with the accepted ``sample``, at t; the nav-frame
        horizontal acceleration once aligned."""
        gyro, accel = self.sample
        if self._t_first is None:
            self._t_first = t
        try:
            if self.sins is None:
                if not self.need_sins or t - self._t_first < self.cfg.alignment_s \
                        or self._last_sample is None:
                    self.alignment.add(gyro, accel)
                    self._last_sample = (gyro, accel)
                    return None
                self._start_strapdown()
            return self.sins.step(t - self.t_imu, gyro, accel)[:2]
        finally:
            self.t_imu = t

    def _start_strapdown(self) -> None:
        c = self.cfg
        self.aligned = a = self.alignment.result(c.heading_rad, math.radians(c.latitude_deg), c.x_azimuth_deg)
        self.sins = Strapdown(position=self.origin, q=a.q, gyro_bias=a.gyro_bias, latitude_deg=c.latitude_deg,
                              local_gravity=c.local_gravity, altitude_m=c.altitude_m, x_azimuth_deg=c.x_azimuth_deg)
        self.sins.step(0.0, *self._last_sample)  # the interval to the next sample starts here
        self.t_aligned = self.t_imu

    def motion(self, t_s: float, acceleration: tuple | None) -> Motion:
        """The Motion product of the sample at t_s: at rest while aligning (acceleration
        None), else the strapdown's acceleration with its tilt-grown R."""
        if acceleration is None:
            return Motion(t_s, "stationary", self._at_rest, self._r_stationary, STATIONARY)
        T = t_s - self.t_aligned
        R = (self._accel_var + self._tilt_growth * T * T) * self._i2
        return Motion(t_s, "accel", np.array(acceleration[:2]), R, ACCELERATION)

    def fix(self, fix) -> None:
        """A WSN fix (host.measurements.Fix): after an IMU restart, until the strapdown realigns,
        the origin is the mean of the fixes since the restart (the vehicle is at rest)."""
        if self.sins is None and self._origin_since is not None and fix.t >= self._origin_since:
            total, n = self._origin_fixes[0] + fix.p, self._origin_fixes[1] + 1
            self._origin_fixes, self.origin = (total, n), tuple((total / n).tolist())

    def restart(self, t_s: float, uptime_s: float) -> None:
        """The IMU restarted at t_s, up *uptime_s*: realign (the vehicle stands still after a
        power-up, like at the start) over the alignment_s since the power-up, or from t_s if
        that is more, at the mean of the fixes from t_s on."""
        self.alignment = Alignment()
        self.sins = None
        self.t_aligned = self._last_sample = None
        self._t_first = self._power_up(t_s, uptime_s)
        self.origin, self._origin_since = tuple(self.cfg.start), t_s
        self._origin_fixes = (np.zeros(2), 0)

    def stats(self) -> dict | None:
        """The alignment's result (None before it ends)."""
        a = self.aligned
        return None if a is None else {
            "samples": a.samples, "roll_rad": a.roll, "pitch_rad": a.pitch, "yaw_rad": a.yaw,
            "gyro_bias_rad_s": [float(v) for v in a.gyro_bias],
            "specific_force_m_s2": a.specific_force}
