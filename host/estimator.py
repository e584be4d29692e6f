"""The fusion core: IMU samples and range exchanges in, one estimate per filter per period out.

Filters (``FILTER_NAMES``):

=====  =====================================================================================
sins   pure strapdown track (host.sins): coarse alignment on the stationary start, then
       mechanization at the IMU rate (000 eqs. 1-5)
wsn    pure WSN track (host.wsn): one TDOA (``wsn_method="toa"``: TOA) fix per TDMA cycle
       (000 eqs. 6-13)
kf     linear KF, loosely coupled: predicts at each IMU sample, measures the SINS nav-frame
       acceleration and each WSN position fix
ekf    EKF, tightly coupled: same prediction and acceleration; measures each cycle's range
       differences to anchor 1 (``tight="toa"``: each range at its own time)
ukf    UKF: as the EKF, through sigma points
=====  =====================================================================================

Time. ``t_s`` is the measurement time (host time base, seconds). The fusion filters keep
one time, the latest measurement's (they are predicted to it lazily, before their next
update or output: one predict then spans the exchanges that updated none of them); a
measurement older than that (the two streams are merged by the caller) is applied with its
lag through the motion model (host.filters.model) if the lag is at most ``max_lag_s``, else
rejected as ``late``. The SINS needs its IMU samples strictly in order; an IMU sample not
after the previous one is rejected.

Output. Estimates are emitted at the instants k * output_period_s of the measurement time
base: an estimate at t_k reflects every measurement with t_s <= t_k, the fusion state
predicted from its last measurement to t_k. They are returned by the ``imu`` / ``range``
call that first passes t_k (nothing comes out before the first measurement), one per
configured filter in ``cfg.filters`` order. The Estimator is a pure function of its call
sequence: no wall clock, no randomness.

Estimate fields: x, y (m), vx, vy (m/s) in the area frame; yaw (rad, 0 along area +x,
counter-clockwise) from the SINS attitude for sins/kf/ekf/ukf (the configured initial heading
until alignment ends), None for wsn; cov = the 4x4 covariance of (x, y, vx, vy), row-major,
16 floats. For wsn: the fix's CRLB covariance and the velocity of the last two fixes
(finite difference) with its propagated covariance; the wsn track holds its last fix
between fixes and starts once two fixes exist. For sins: the initial covariance plus the
growth that the accelerometer's velocity random walk alone causes (a lower bound: tilt and
heading errors add to it). ``extrapolated``: the track's last aiding is more than
``extrapolated_after_s`` before t (kf/ekf/ukf: an accepted fix, TDOA or range update; wsn: a
fix; sins: an IMU sample; the configured start counts as aiding at the first measurement),
or a fusion track waits to re-initialise.

Discontinuities (docs/filters.md). A fusion track that cannot explain what it measures
starts again from the next WSN fix newer than the discontinuity (position and covariance of
the fix, at rest with ``reinit_sigma`` on velocity and acceleration), counted by cause in
``stats()["reinit"]``: ``restart`` (:meth:`Estimator.restart`: a device's clock began a new
epoch), ``gated`` (every position update gated out for ``gate_reopen_s``). A restart also
drops the wsn track's velocity history and, for the IMU, realigns the strapdown on the
stationary start, placed at the mean of the fixes during the alignment (the configured start
without any).
"""
from __future__ import annotations

import math
from collections import Counter, defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from protocols.nanoloc import STATUS_TIMEOUT, is_complete

from .filters import (ACCELERATION, ConstantAcceleration, ExtendedKalmanFilter, KalmanFilter,
                      Linear, Ranges, UnscentedKalmanFilter, position_fix)
from .sins import Alignment, AlignmentResult, Strapdown
from .wsn import AnchorLayout, CycleGrouper, Fix, Solver, chi2_gate, tdoa_covariance

FILTER_NAMES = ("sins", "wsn", "kf", "ekf", "ukf")
FUSION = ("kf", "ekf", "ukf")
DEVICES = ("imu", "anchors")  # what can restart (Estimator.restart)
POSITION_KINDS = frozenset(("fix", "tdoa", "range"))  # the updates that aid a track's position
OFFICE_ANCHORS = {1: (1.3, 1.6, 0.0), 2: (10.8, 1.6, 0.0), 3: (10.8, 5.4, 0.0), 4: (1.3, 5.4, 0.0)}

#: At rest: velocity and acceleration are zero (used while the alignment runs).
STATIONARY = Linear(np.hstack([np.zeros((4, 2)), np.eye(4)]))


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything the estimator needs; the defaults are 000's office lab."""

    anchors: Mapping[int, tuple[float, ...]] = field(default_factory=lambda: dict(OFFICE_ANCHORS))
    tag_height: float = 0.0  # m, same datum as the anchors' z
    latitude_deg: float = 34.316
    gravity: float = 9.7952  # m/s^2, local
    altitude_m: float = 0.0
    x_azimuth_deg: float = 90.0  # azimuth of the area's +x, clockwise from north (90: x east)
    filters: tuple[str, ...] = FILTER_NAMES
    start: tuple[float, float] = (6.0, 1.8)  # m, where the vehicle rests during alignment
    heading0_rad: float = 0.0  # initial heading (MEMS gyros cannot gyrocompass)
    alignment_s: float = 5.0  # stationary period from the first IMU sample
    gyro_range_dps: int = 300  # ADIS16350 range: the service's word scale; counts overrange
    output_period_s: float = 0.1
    # noise and tuning
    range_sigma_m: float = 0.4  # one exchange's distance, 1 sigma
    range_bias_m: Mapping[int, float] = field(default_factory=dict)  # c_i of 001: calibrated delays
    range_scale: float = 1.0  # f of 001: distance = (reported - c_i) / f
    vrw_m_s_rt_hr: float = 2.0  # ADIS16350 velocity random walk (the sins track's covariance)
    arw_deg_rt_hr: float = 4.2  # ADIS16350 angle random walk
    gyro_bias_instability_dps: float = 0.015  # ADIS16350 in-run bias stability
    # SINS acceleration as a measurement (docs/filters.md): sigma^2 = accel_sigma_m_s2^2 +
    # (tilt_inflation g s T)^2, s = the tilt rate the alignment leaves, T = time since it
    accel_sigma_m_s2: float = 1.0
    tilt_inflation: float = 10.0
    jerk_psd: float = 0.5  # m^2/s^5, constant-acceleration model's white jerk
    p0_sigma: tuple[float, float, float] = (0.2, 0.02, 0.1)  # initial position, velocity, accel
    stationary_sigma: tuple[float, float] = (0.01, 0.05)  # velocity, accel while aligning
    gate_probability: float = 0.9999  # chi-square innovation gate
    gate_reopen_s: float = 2.0  # every update of one kind gated out this long: the track is off
    reinit_sigma: tuple[float, float] = (1.0, 1.0)  # velocity (m/s), acceleration (m/s^2) of a re-init
    extrapolated_after_s: float = 0.5  # no aiding for longer than this: an estimate is extrapolated
    wsn_method: str = "tdoa"  # pure-WSN and KF fixes: "toa" | "tdoa" (000 eqs. 12-13)
    tight: str = "tdoa"  # EKF/UKF range measurement: "tdoa" (per cycle) | "toa" (each range)
    reference_anchor: int = 1  # TDOA reference (000 eq. 12)
    cycle_s: float = 0.1  # TDMA cycle: exchanges grouped within this window
    max_lag_s: float = 0.5
    max_range_m: float = 100.0
    fix_margin_m: float | None = 2.0  # WSN fixes beyond the anchors' box grown by this are refused
    ukf_alpha: float = 1.0
    ukf_beta: float = 2.0
    ukf_kappa: float | None = None  # None: 3 - n

    def __post_init__(self):
        unknown = [f for f in self.filters if f not in FILTER_NAMES]
        if unknown or not self.filters:
            raise ValueError(f"filters: unknown {unknown or 'empty list'}; use some of {','.join(FILTER_NAMES)}")
        for name in ("wsn_method", "tight"):
            if getattr(self, name) not in ("toa", "tdoa"):
                raise ValueError(f"{name}: {getattr(self, name)!r} is not a method; use 'toa' or 'tdoa'")
        for name in ("alignment_s", "output_period_s", "range_sigma_m", "range_scale", "vrw_m_s_rt_hr",
                     "arw_deg_rt_hr", "accel_sigma_m_s2", "jerk_psd", "cycle_s", "max_range_m",
                     "gate_reopen_s", "extrapolated_after_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number (got {value}); set a value > 0")
        for name in ("gyro_bias_instability_dps", "tilt_inflation"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be a number >= 0 (got {getattr(self, name)}); set a value >= 0")
        for name, n in (("p0_sigma", 3), ("stationary_sigma", 2), ("reinit_sigma", 2)):
            value = getattr(self, name)
            if len(value) != n or not all(math.isfinite(v) and v > 0 for v in value):
                raise ValueError(f"{name} must hold {n} positive numbers (got {value}); set {n}, each > 0")
        if not 0 < self.gate_probability < 1:
            raise ValueError(f"gate_probability must be in (0, 1) (got {self.gate_probability}); use e.g. 0.9999")
        if len(self.anchors) < 3:
            raise ValueError(f"anchors: {len(self.anchors)} given; a 2-D fix needs at least 3, list them all")

    @property
    def tilt_rate_sigma(self) -> float:
        """rad/s: gyro bias error left by averaging ARW over the alignment, and the bias's
        in-run wander; the tilt error grows as this times the time since the alignment."""
        arw = math.radians(self.arw_deg_rt_hr) / 60.0  # rad/sqrt(s)
        return math.sqrt(arw**2 / self.alignment_s + math.radians(self.gyro_bias_instability_dps) ** 2)


@dataclass(frozen=True, slots=True)
class Estimate:
    t: float
    filter: str
    x: float
    y: float
    vx: float
    vy: float
    yaw: float | None
    cov: list[float]  # 4x4 covariance of (x, y, vx, vy), row-major
    extrapolated: bool = False  # the track had no aiding for extrapolated_after_s before t


def _estimate(t, name, p, v, yaw, cov4, extrapolated: bool) -> Estimate:
    """p, v: sequences of 2; cov4: a 4x4 array, or its 16 floats row-major."""
    (x, y), (vx, vy) = np.asarray(p, float).tolist(), np.asarray(v, float).tolist()
    cov = cov4 if isinstance(cov4, list) else np.ravel(cov4).tolist()
    return Estimate(float(t), name, x, y, vx, vy, None if yaw is None else float(yaw), cov,
                    bool(extrapolated))


class Estimator:
    def __init__(self, cfg: EstimatorConfig | None = None):
        self.cfg = cfg = cfg or EstimatorConfig()
        self.layout = AnchorLayout(cfg.anchors, cfg.tag_height)
        self.model = ConstantAcceleration(cfg.jerk_psd)
        self.fusion = [f for f in cfg.filters if f in FUSION]
        self.need_sins = any(f != "wsn" for f in cfg.filters)
        self.solver = Solver(self.layout, cfg.range_sigma_m, cfg.wsn_method, cfg.reference_anchor,
                             cfg.gate_probability, cfg.fix_margin_m)
        self.grouper = CycleGrouper(len(self.layout.ids), cfg.cycle_s)
        self.filters: dict[str, KalmanFilter | UnscentedKalmanFilter] = {}
        self.alignment = Alignment()
        self.aligned: AlignmentResult | None = None
        self.sins: Strapdown | None = None
        self._t: float | None = None  # filter time: the latest measurement's
        self._t_predicted: float | None = None  # the fusion filters' state is predicted to here
        self._t_first: float | None = None  # the first measurement's: the start is known then
        self._t_imu_first: float | None = None
        self._t_imu: float | None = None
        self._t_aligned: float | None = None
        self._last_sample: tuple[tuple, tuple] | None = None  # (gyro, accel)
        self._k_out = 0  # next output instant: k * output_period_s
        self._next_out = 0.0  # its time
        self._fixes: list[Fix] = []
        self._gated_since: dict[tuple[str, str], float] = {}  # first rejection of a run of them
        self._origin = tuple(cfg.start)  # where the strapdown starts when its alignment ends
        self._origin_since: float | None = None  # after an IMU restart: the fixes from then on,
        self._origin_fixes = (np.zeros(2), 0)  # summed and counted, give it (at rest: their mean)
        self._reinit: dict[str, float] = {}  # fusion track -> a fix newer than this restarts it
        self._aided: dict[str, float] = {}  # fusion track -> time of its last position update
        self.reinits: defaultdict[str, Counter] = defaultdict(Counter)  # track -> cause -> n
        self.reinit_count = 0  # all of them: one int to watch for a new one
        self._tilt_growth = (cfg.tilt_inflation * cfg.gravity * cfg.tilt_rate_sigma) ** 2
        self._accel_var = cfg.accel_sigma_m_s2**2
        self._range_bias = {int(a): float(c) for a, c in cfg.range_bias_m.items()}
        sv, sa = cfg.stationary_sigma
        self._r_stationary = np.diag([sv**2, sv**2, sa**2, sa**2])
        self._at_rest = np.zeros(4)
        self._i2 = np.eye(2)
        self._gyro_limit = math.radians(cfg.gyro_range_dps)
        self.counts: Counter = Counter()
        self.input_rejections: Counter = Counter()
        self.updates: defaultdict[str, Counter] = defaultdict(Counter)
        self.rejections: defaultdict[str, Counter] = defaultdict(Counter)
        self.emitted: Counter = Counter()

    # ---------------------------------------------------------------- inputs

    def imu(self, t_s: float, gyro_rad_s, accel_m_s2, nd_ok: bool = True) -> list[Estimate]:
        """One IMU sample (body axes: x forward, y left, z up) at measurement time t_s;
        ``nd_ok`` False (ND clear: the registers were not updated) skips it."""
        self.counts["imu"] += 1
        # plain floats: the strapdown's arithmetic is faster on them than on small arrays
        gyro = tuple(map(float, gyro_rad_s))
        accel = tuple(map(float, accel_m_s2))
        if not (math.isfinite(t_s) and all(map(math.isfinite, gyro)) and all(map(math.isfinite, accel))):
            self.input_rejections["imu_implausible"] += 1
            return []
        if not nd_ok:  # a repeated register read: the next sample covers the interval
            self.input_rejections["imu_stale"] += 1
            return []
        if self._t_imu is not None and t_s <= self._t_imu:
            self.input_rejections["imu_out_of_order"] += 1
            return []
        if max(map(abs, gyro)) >= self._gyro_limit:
            self.counts["imu_overrange"] += 1  # saturated, still the best reading there is
        out = self._begin(t_s)
        acceleration = self._sins_step(t_s, gyro, accel)
        if acceleration is None:
            kind, z, R, meas = "stationary", self._at_rest, self._r_stationary, STATIONARY
        else:
            T = t_s - self._t_aligned
            kind, z, meas = "accel", np.array(acceleration[:2]), ACCELERATION
            R = (self._accel_var + self._tilt_growth * T * T) * self._i2
        for name in self.fusion:
            self._update(name, kind, z, R, meas, t_s)
        return self._end(t_s, out)

    def range(self, t_s: float, anchor: int, distance_m: float | None, rssi_dbm: int = 0,
              status: int = 0x0F) -> list[Estimate]:
        """One exchange report; ``distance_m`` None when the exchange did not complete."""
        self.counts["exchanges"] += 1
        if anchor not in self.layout:
            self.input_rejections["unknown_anchor"] += 1
            return []
        if not math.isfinite(t_s):
            self.input_rejections["range_implausible"] += 1
            return []
        out = self._begin(t_s)
        d = None
        if distance_m is None or not is_complete(status):
            self.input_rejections["outage" if status & STATUS_TIMEOUT else "incomplete"] += 1
        elif not (math.isfinite(distance_m) and 0.0 < distance_m <= self.cfg.max_range_m):
            self.input_rejections["range_implausible"] += 1
        else:
            d = (float(distance_m) - self._range_bias.get(anchor, 0.0)) / self.cfg.range_scale
            if self.cfg.tight == "toa":
                meas = Ranges(self.layout, (anchor,), (max(self._t - t_s, 0.0),))
                for name in self.fusion:
                    if name != "kf":
                        self._update(name, "range", np.array([d]),
                                     np.array([[self.cfg.range_sigma_m**2]]), meas, t_s)
        for cycle in self.grouper.add(t_s, anchor, d):
            self._cycle(cycle)
        return self._end(t_s, out)

    def restart(self, t_s: float, device: str, uptime_s: float = 0.0) -> list[Estimate]:
        """``device`` (one of ``DEVICES``) restarted: its clock began a new epoch at t_s, so
        what the tracks hold need not be where the vehicle is. The fusion tracks start again
        from the next fix, the wsn track drops its velocity history; an IMU restart also
        realigns the strapdown (the vehicle stands still after a power-up, like at the start)
        over the alignment_s since the power-up, ``uptime_s`` before t_s (its sample counter
        says; the host may see the board only after a while), or from t_s if that is more."""
        if device not in DEVICES:
            raise ValueError(f"device {device!r}: use one of {', '.join(DEVICES)}")
        if not math.isfinite(t_s):
            self.input_rejections["restart_implausible"] += 1
            return []
        out = self._begin(t_s)
        self.grouper = CycleGrouper(len(self.layout.ids), self.cfg.cycle_s)  # no cycle spans it
        if self._fixes and "wsn" in self.cfg.filters:
            self._count_reinit("wsn", "restart")
        self._fixes = []
        for name in self.fusion:
            self._discontinuity(name, "restart", t_s)
        if device == "imu":
            if "sins" in self.cfg.filters:
                self._count_reinit("sins", "restart")
            self.alignment = Alignment()
            self.sins = None
            self._t_aligned = self._last_sample = None
            self._t_imu_first = t_s - uptime_s if 0.0 <= uptime_s < self.cfg.alignment_s else None
            self._origin, self._origin_since = tuple(self.cfg.start), t_s
            self._origin_fixes = (np.zeros(2), 0)
        return self._end(t_s, out)

    # ---------------------------------------------------------------- processing

    def _begin(self, t: float) -> list[Estimate]:
        """Start the filters at the first measurement; emit the instants before t."""
        if self._t is None:
            self._t = self._t_predicted = self._t_first = t
            self._k_out = math.ceil(t / self.cfg.output_period_s)
            self._next_out = self._k_out * self.cfg.output_period_s
            self._init_filters()
        out = self._emit(t, through=False) if self._next_out < t else []
        self._t = max(self._t, t)
        return out

    def _predict(self) -> None:
        """Predict the fusion filters to the filter time. Lazily, before their next update:
        over measurements that update none of them (most exchanges), F(dt1 + dt2) =
        F(dt2) F(dt1) and the Q likewise make one predict the same as several."""
        dt = self._t - self._t_predicted
        for name in self.fusion:
            try:
                self.filters[name].predict(dt)
            except np.linalg.LinAlgError:
                self._reset(name)
        self._t_predicted = self._t

    def _end(self, t: float, out: list[Estimate]) -> list[Estimate]:
        """out and the estimates of the output instants up to t."""
        return out + self._emit(t, through=True) if self._next_out <= t else out

    def _init_filters(self, only: str | None = None) -> None:
        c = self.cfg
        if only is None:
            x0 = np.array([*c.start, 0.0, 0.0, 0.0, 0.0])
        else:  # a reset: the latest WSN fix, else the SINS
            p = self._fixes[-1].p if self._fixes else self.sins.p[:2] if self.sins else c.start
            v = self.sins.v[:2] if self.sins else (0.0, 0.0)
            x0 = np.array([*p, *v, 0.0, 0.0])
        sp, sv, sa = c.p0_sigma
        P0 = np.diag([sp**2, sp**2, sv**2, sv**2, sa**2, sa**2])
        for name in ([only] if only else self.fusion):
            self._new_filter(name, x0, P0)

    def _new_filter(self, name: str, x0: np.ndarray, P0: np.ndarray) -> None:
        c = self.cfg
        if name == "kf":
            f = KalmanFilter(x0, P0, self.model)
        elif name == "ekf":
            f = ExtendedKalmanFilter(x0, P0, self.model)
        else:
            f = UnscentedKalmanFilter(x0, P0, self.model, c.ukf_alpha, c.ukf_beta, c.ukf_kappa)
        self.filters[name] = f
        if self._gated_since:  # a new track has no run of rejections
            self._gated_since = {k: v for k, v in self._gated_since.items() if k[0] != name}

    def _count_reinit(self, name: str, cause: str) -> None:
        self.reinits[name][cause] += 1
        self.reinit_count += 1

    def _discontinuity(self, name: str, cause: str, t: float) -> None:
        """Fusion track ``name`` is off for ``cause``: it starts again from the next fix newer
        than t (counted once per discontinuity, however many causes it has)."""
        if name not in self._reinit:
            self._count_reinit(name, cause)
        self._reinit[name] = t

    def _reinit_at(self, name: str, fix: Fix) -> None:
        """Start fusion track ``name`` again at ``fix``: its position and covariance, at rest
        but with ``reinit_sigma`` on velocity and acceleration (they are unknown)."""
        sv, sa = self.cfg.reinit_sigma
        P0 = np.diag([0.0, 0.0, sv**2, sv**2, sa**2, sa**2])
        P0[:2, :2] = fix.cov
        self._new_filter(name, np.array([*fix.p, 0.0, 0.0, 0.0, 0.0]), P0)
        del self._reinit[name]
        self._aided[name] = fix.t

    def _sins_step(self, t: float, gyro: tuple, accel: tuple) -> tuple | None:
        """Advance alignment or strapdown; the nav-frame horizontal acceleration once aligned."""
        if self._t_imu_first is None:
            self._t_imu_first = t
        try:
            if self.sins is None:
                if not self.need_sins or t - self._t_imu_first < self.cfg.alignment_s \
                        or self._last_sample is None:
                    self.alignment.add(gyro, accel)
                    self._last_sample = (gyro, accel)
                    return None
                self._start_strapdown()
            return self.sins.step(t - self._t_imu, gyro, accel)[:2]
        finally:
            self._t_imu = t

    def _start_strapdown(self) -> None:
        c = self.cfg
        self.aligned = a = self.alignment.result(c.heading0_rad, math.radians(c.latitude_deg), c.x_azimuth_deg)
        self.sins = Strapdown(position=self._origin, q=a.q, gyro_bias=a.gyro_bias, latitude_deg=c.latitude_deg,
                              gravity=c.gravity, altitude_m=c.altitude_m, x_azimuth_deg=c.x_azimuth_deg)
        self.sins.step(0.0, *self._last_sample)  # the interval to the next sample starts here
        self._t_aligned = self._t_imu

    def _update(self, name: str, kind: str, z, R, meas, t: float) -> None:
        """One gated update of filter ``name``; counts the outcome by kind or reason."""
        lag = self._t - t
        if lag > self.cfg.max_lag_s:
            self.rejections[name]["late"] += 1
            return
        if self._t_predicted < self._t:
            self._predict()
        f = self.filters[name]
        try:
            inn = f.update(z, R, meas, chi2_gate(meas.dim, self.cfg.gate_probability))
            if not inn.accepted:
                gated_for = t - self._gated_since.setdefault((name, kind), t)
                if gated_for > self.cfg.gate_reopen_s and kind not in POSITION_KINDS:
                    # the acceleration gated out for so long: the track's acceleration is off
                    self.rejections[name]["gate_reopened"] += 1
                    f.update(z, R, meas)
                else:
                    self.rejections[name]["gate"] += 1
                    if gated_for > self.cfg.gate_reopen_s:
                        # every position update gated out for so long: the track, not the WSN, is off
                        self._discontinuity(name, "gated", t)
                    return
        except np.linalg.LinAlgError:
            self._reset(name)
            return
        if self._gated_since:
            self._gated_since.pop((name, kind), None)
        if kind in POSITION_KINDS:
            self._aided[name] = t
        self.updates[name][kind] += 1

    def _reset(self, name: str) -> None:
        """A covariance lost positive definiteness (never seen; rounding can do it)."""
        self.rejections[name]["numerical_reset"] += 1
        self._init_filters(only=name)

    def _cycle(self, cycle) -> None:
        """A closed TDMA cycle: the WSN fix (wsn track, KF, re-initialisations, the SINS origin
        after a restart) and the TDOA update (EKF/UKF). A track started again at this cycle's
        fix takes no other update from it (the same ranges)."""
        fix = self.solver.fix(cycle.t, cycle.valid_anchors, cycle.distances)
        fresh: list[str] = []
        if isinstance(fix, str):
            self.rejections["wsn"][fix] += 1
        else:
            self.updates["wsn"]["fix"] += 1
            if fix.dropped:
                self.rejections["wsn"]["outlier_dropped"] += 1
            # two fixes with one time would give no velocity: keep the newer
            older = [f for f in self._fixes[-1:] if f.t < fix.t]
            self._fixes = [*older, fix]
            if self.sins is None and self._origin_since is not None and fix.t >= self._origin_since:
                total, n = self._origin_fixes[0] + fix.p, self._origin_fixes[1] + 1
                self._origin_fixes, self._origin = (total, n), tuple((total / n).tolist())
            fresh = [n for n, since in self._reinit.items() if fix.t >= since]
            for name in fresh:
                self._reinit_at(name, fix)
            if "kf" in self.fusion and "kf" not in fresh:
                self._update("kf", "fix", fix.p, fix.cov, position_fix(max(self._t - fix.t, 0.0)), fix.t)
        tight = [n for n in self.fusion if n != "kf" and n not in fresh]
        if self.cfg.tight == "tdoa" and tight:
            self._tdoa_update(cycle, tight)

    def _tdoa_update(self, cycle, tight: list[str]) -> None:
        """Range differences to the reference anchor (000 eqs. 12-13), R = sigma^2 (I + 11^T)."""
        r = dict(zip(cycle.valid_anchors, cycle.distances))
        t_of = dict(zip(cycle.valid_anchors, cycle.valid_times))
        ref = self.cfg.reference_anchor if self.cfg.reference_anchor in r else min(r, default=None)
        # |r_i - r_ref| cannot exceed the anchors' separation (triangle inequality), give or
        # take 4 sigma of the difference's noise (it is tight on the line through the two)
        slack = 4.0 * math.sqrt(2.0) * self.cfg.range_sigma_m
        others = []
        for a in r:
            if a != ref and abs(r[a] - r[ref]) <= self.layout.baseline(a, ref) + slack:
                others.append(a)
            elif a != ref:
                for name in tight:
                    self.rejections[name]["implausible"] += 1
        if len(others) < 2:
            for name in tight:
                self.rejections[name]["too_few"] += 1
            return
        keep = [ref, *others]
        z = np.array([r[a] - r[ref] for a in others])
        meas = Ranges(self.layout, keep, [max(self._t - t_of[a], 0.0) for a in keep], reference=ref)
        R = tdoa_covariance(self.cfg.range_sigma_m, len(others))
        for name in tight:
            self._update(name, "tdoa", z, R, meas, cycle.t)

    # ---------------------------------------------------------------- output

    def _emit(self, t: float, through: bool) -> list[Estimate]:
        """The estimates of the output instants before t (``through``: up to t inclusive)."""
        out = []
        while (b := self._next_out) < t or (through and b == t):
            yaw = self.sins.yaw if self.sins is not None else self.cfg.heading0_rad
            for name in self.cfg.filters:
                e = self._snapshot(name, b, yaw)
                if e is not None:
                    out.append(e)
                    self.emitted[name] += 1
            self._k_out += 1
            self._next_out = self._k_out * self.cfg.output_period_s
        return out

    def _snapshot(self, name: str, b: float, yaw: float) -> Estimate | None:
        if name in FUSION:
            x, P = self.model.propagate(self.filters[name].x, self.filters[name].P, b - self._t_predicted)
            stale = name in self._reinit or self._stale(b, self._aided.get(name))  # waiting: off
            return _estimate(b, name, x[:2], x[2:4], yaw, P[:4, :4], stale)
        if name == "sins":
            return self._sins_snapshot(b, yaw)
        return self._wsn_snapshot(b)

    def _stale(self, b: float, t_aided: float | None) -> bool:
        """Whether an estimate at b, last aided at t_aided (None: never, only the configured
        start at the first measurement), is extrapolated."""
        return b - (self._t_first if t_aided is None else t_aided) > self.cfg.extrapolated_after_s

    def _sins_snapshot(self, b: float, yaw: float) -> Estimate:
        sp, sv, _ = self.cfg.p0_sigma
        pp, pv, vv = float(sp) ** 2, 0.0, float(sv) ** 2
        if self.sins is None:
            p, v = self._origin, (0.0, 0.0)
        else:
            dt = b - self._t_imu
            v = self.sins.v[:2]
            p = self.sins.p[:2] + v * dt
            # velocity random walk q per axis: P_pp = q T^3/3, P_pv = q T^2/2, P_vv = q T
            T = b - self._t_aligned
            q = (self.cfg.vrw_m_s_rt_hr / 60.0) ** 2
            pp, pv, vv = pp + q * (T**3 / 3), pv + q * (T**2 / 2), vv + q * T
        cov = [pp, 0.0, pv, 0.0, 0.0, pp, 0.0, pv, pv, 0.0, vv, 0.0, 0.0, pv, 0.0, vv]  # (x, y) alike
        return _estimate(b, "sins", p, v, yaw, cov, self._stale(b, self._t_imu))

    def _wsn_snapshot(self, b: float) -> Estimate | None:
        if len(self._fixes) < 2:
            return None
        f0, f1 = self._fixes
        dt = f1.t - f0.t
        v = (f1.p - f0.p) / dt
        cov = np.empty((4, 4))  # [[C1, C1/dt], [C1/dt, (C0 + C1)/dt^2]]
        cov[:2, :2] = f1.cov
        cov[:2, 2:] = cov[2:, :2] = f1.cov / dt
        cov[2:, 2:] = (f0.cov + f1.cov) / dt**2
        return _estimate(b, "wsn", f1.p, v, None, cov, self._stale(b, f1.t))

    # ---------------------------------------------------------------- status

    def stats(self) -> dict:
        """Counts: inputs, input rejections, updates and rejections per filter by kind/reason,
        estimates emitted, and the alignment result."""
        a = self.aligned
        return {
            "imu_samples": self.counts["imu"],
            "imu_overrange": self.counts["imu_overrange"],
            "exchanges": self.counts["exchanges"],
            "input_rejections": dict(sorted(self.input_rejections.items())),
            "updates": {n: dict(sorted(self.updates[n].items())) for n in self.cfg.filters if n != "sins"},
            "rejections": {n: dict(sorted(self.rejections[n].items())) for n in self.cfg.filters
                           if n != "sins"},
            "estimates": {n: self.emitted[n] for n in self.cfg.filters},
            "reinit": {n: dict(sorted(self.reinits[n].items())) for n in self.cfg.filters if self.reinits[n]},
            "reinit_pending": [n for n in self.cfg.filters if n in self._reinit],
            "alignment": None if a is None else {
                "samples": a.samples, "roll_rad": a.roll, "pitch_rad": a.pitch, "yaw_rad": a.yaw,
                "gyro_bias_rad_s": [float(v) for v in a.gyro_bias],
                "specific_force_m_s2": a.specific_force},
        }
