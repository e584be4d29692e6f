"""The fusion core for N seeds at once: each seed's records in, each seed's estimates out,
equal to host.estimator.Estimator fed the same records alone (issue 23's batch engine).

The seeds are independent, so the core may interleave them in any way that keeps each
seed's own order: every round takes each seed's next record, and the seeds whose next
record is an IMU sample are stepped together (the checks, the alignment, the strapdown,
the Motion product, the tracks' updates, the output instants), then those whose next is an
exchange. What the per-seed estimator does per record it does here for the rows ``idx``
of the seeds concerned, in the same order and with the same arithmetic (host.batch's
filters, host.batch.strapdown), so each seed's numbers are the per-seed estimator's.

The common path only. A seed whose records hold anything else (a device restart, an IMU
sample out of order or stale, a gap in the IMU stream too long to bridge, a record type no
twin takes),
or whose tracks would take a branch their twins do not carry (a numerical reset, an
estimate that is not finite), is *ejected*: :attr:`ejected` names it, its rows are dropped, and the caller
runs it per seed with the estimator itself (lab.batch). Everything the per-seed estimator
does on that path therefore needs no twin here.

Ranging (the exchanges' checks, TDMA cycles, fixes and Tdoa products) is batched too:
host.batch.ranging, each seed's open cycle and last fixes in arrays.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


from ..estimator import IGNORED_UNTAKEN
from ..filters import ACCELERATION, ConstantAcceleration
from ..inertial import STATIONARY
from ..measurements import Exchange, Fix, FixRefused, ImuSample, Motion, Range, Tdoa
from ..settings import EstimatorConfig
from ..sins import Alignment
from ..wsn import AnchorLayout
from . import tracks as batch_tracks
from .kf import propagate
from .ranging import BatchRanging
from .seeds import whole
from .strapdown import BatchStrapdown

#: what a seed's next record is: an IMU sample, an exchange, a record only the tracks run per
#: seed take (it moves the filter time: the estimator feeds it to them), one nobody takes
IMU, EXCHANGE, TIMED, SKIP = 0, 1, 2, 3


class MotionBatch(NamedTuple):
    """host.measurements.Motion of the seeds ``idx``: one kind, z (n, m), R (n, m, m) or
    (m, m) shared, its Linear measurement, t (n,)."""
    kind: str
    t: np.ndarray
    z: np.ndarray
    R: np.ndarray
    meas: object


class FixBatch(NamedTuple):
    """host.measurements.Fix of the seeds ``idx``: t (n,), p (n, 2), cov (n, 2, 2), and each
    fix's number in its seed (host.batch.ranging: a track that started again at one takes no
    other update of its cycle)."""
    t: np.ndarray
    p: np.ndarray
    cov: np.ndarray
    number: np.ndarray


class ImuBatch(NamedTuple):
    """host.measurements.ImuSample of the seeds ``idx`` (all taken): t (n,), gyro, accel (n, 3)."""
    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray


class RangeBatch(NamedTuple):
    """host.measurements.Range of the seeds ``idx``: the exchange's t (n,), the corrected
    distance z (n,), the anchor's ``row`` in the layout (n,), the lag to the filter time
    (n,); R = range_sigma_m^2 (Ranging.range)."""
    t: np.ndarray
    z: np.ndarray
    row: np.ndarray
    lag: np.ndarray


class Unbatchable(ValueError):
    """A seed's records leave the common path (the reason); it runs per seed."""


class Stream(NamedTuple):
    """One seed's records as arrays: ``kind`` and ``t`` per record; the IMU samples' gyro,
    accel (n, 3) and uptime (NaN: none) at their records; the exchanges' anchor ids, reported
    distances (NaN: none) and statuses at theirs."""
    kind: np.ndarray
    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    uptime: np.ndarray
    anchor: np.ndarray
    distance: np.ndarray
    status: np.ndarray


def stream(records: list, takes: frozenset, taken: frozenset, gap_s: float) -> Stream:
    """*records* as a :class:`Stream`; :class:`Unbatchable` when one leaves the common path.
    *takes*: the types the batch's tracks take (:meth:`BatchEstimator.takes`); *taken*: those
    the tracks run per seed beside it take (host.estimator.Estimator.takes); *gap_s*: the
    estimator's ``imu_gap_s`` (a shorter gap is bridged: the next step spans it, nothing
    else changes; a longer one restarts the tracks)."""
    n = len(records)
    kind = np.full(n, SKIP, np.int8)
    t = np.zeros(n)
    gyro, accel = np.zeros((n, 3)), np.zeros((n, 3))
    uptime = np.full(n, np.nan)
    anchor, distance, status = np.zeros(n, np.int64), np.full(n, np.nan), np.zeros(n, np.int64)
    last = -math.inf
    for i, r in enumerate(records):
        cls = type(r)
        if cls is ImuSample:
            g, a = tuple(map(float, r.gyro)), tuple(map(float, r.accel))
            if not (math.isfinite(r.t) and all(map(math.isfinite, g + a))):
                raise Unbatchable("IMU sample not finite")
            if not r.nd_ok:
                raise Unbatchable("IMU sample stale")
            if r.t <= last:
                raise Unbatchable("IMU sample out of order")
            if last > -math.inf and r.t - last > gap_s:  # Inertial.gap: the tracks start again
                raise Unbatchable("IMU gap")
            if r.uptime_s is not None and i and last > -math.inf:
                raise Unbatchable("IMU uptime after the first sample")
            kind[i], t[i], gyro[i], accel[i], last = IMU, r.t, g, a, r.t
            if r.uptime_s is not None:
                uptime[i] = r.uptime_s
        elif cls is Exchange:
            kind[i], t[i], anchor[i], status[i] = EXCHANGE, r.t, r.anchor, r.status
            if r.distance is not None:
                distance[i] = r.distance
        elif cls in IGNORED_UNTAKEN and cls not in takes:
            if cls in taken and math.isfinite(r.t):
                kind[i], t[i] = TIMED, r.t
        else:
            raise Unbatchable(f"{cls.__name__} record")
    return Stream(kind, t, gyro, accel, uptime, anchor, distance, status)


#: The column names of one track's estimates, per seed (:meth:`BatchEstimator.run`; lab.batch's
#: ``columns`` of the per-seed estimator's give the same): ``cov`` the 4x4 of x, y, vx, vy as
#: (k, 16), ``yaw`` NaN where the track reports none.
COLUMNS = ("t", "x", "y", "vx", "vy", "yaw", "cov", "extrapolated")


class BatchEstimator:
    """host.estimator.Estimator for N seeds and the tracks of *cfg* that have a batch twin
    (host.batch.tracks; the caller runs the others per seed)."""

    def __init__(self, cfg: EstimatorConfig, n: int) -> None:
        self.cfg, self.n = cfg, n
        self.layout = AnchorLayout(cfg.anchors, cfg.tag_height)
        self.model = ConstantAcceleration(cfg.jerk_psd)
        self.tracks = [batch_tracks.get(name)(self, cfg.settings.get(name)) for name in cfg.filters]
        self._takers: dict[type, list] = {}
        for track in self.tracks:
            for kind, handler in track.handlers().items():
                self._takers.setdefault(kind, []).append(handler)
        self.need_sins = any(track.uses_strapdown for track in self.tracks)
        nan = np.full(n, np.nan)
        # the time base (host.timebase.FilterTime)
        self.started = np.zeros(n, bool)
        self.t, self.t_first = nan.copy(), nan.copy()
        self.k_out = np.zeros(n, np.int64)
        self.next_out = np.zeros(n)
        # the inertial part (host.inertial.Inertial)
        self.t_imu, self.t_power_up, self.t_aligned = nan.copy(), nan.copy(), nan.copy()
        self.aligned = np.zeros(n, bool)
        self.align_n = np.zeros(n, np.int64)
        self.align_gyro, self.align_accel = np.zeros((n, 3)), np.zeros((n, 3))
        self.last = np.zeros((n, 6))  # the alignment's last sample
        self.has_last = np.zeros(n, bool)
        # every strapdown of the batch in one stack, stepped by one call a sample: the
        # estimator's rows, then those of each track with a strapdown of its own
        self._owners = [track for track in self.tracks if track.own_strapdown]
        self._strapdowns = BatchStrapdown(n * (1 + len(self._owners)), latitude_deg=cfg.latitude_deg,
                                          altitude_m=cfg.altitude_m, x_azimuth_deg=cfg.x_azimuth_deg)
        self.sins = self._strapdowns.part(0, n)
        for k, track in enumerate(self._owners, 1):
            track.nav = self._strapdowns.part(k * n, n)
        # the constant-acceleration tracks' states in one stack too, predicted in one call
        self._ca = [track for track in self.tracks if track.ca_state]
        self._ca_x, self._ca_P = np.zeros((len(self._ca) * n, 6)), np.zeros((len(self._ca) * n, 6, 6))
        self._ca_t = np.full(len(self._ca) * n, np.nan)
        for k, track in enumerate(self._ca):
            track.x, track.P, track.t_predicted = (a[k * n:(k + 1) * n] for a in
                                                   (self._ca_x, self._ca_P, self._ca_t))
        self._tilt_growth = (cfg.tilt_inflation * cfg.local_gravity * cfg.tilt_rate_sigma) ** 2
        self._accel_var = cfg.accel_sigma_m_s2 ** 2
        sv, sa = cfg.stationary_sigma
        self._r_stationary = np.diag([sv**2, sv**2, sa**2, sa**2])
        self.ranging = BatchRanging(cfg, self.layout, n)  # its last two fixes for the tracks
        self.ejected: dict[int, str] = {}
        self._alive = np.ones(n, bool)
        self._out: dict[str, list] = {track.name: [] for track in self.tracks}

    # ---------------------------------------------------------------- the run

    def run(self, streams: list[Stream]) -> list[dict]:
        """Each seed's estimates per track (``columns``' layout): the seeds of *streams*
        in order; an ejected seed's dict is empty (see :attr:`ejected`)."""
        if len(streams) != self.n:
            raise ValueError(f"{len(streams)} streams for {self.n} seeds; give one per seed")
        length = np.array([len(s.kind) for s in streams])
        width = int(length.max(initial=0))
        kind = np.full((self.n, width + 1), -1, np.int8)
        t = np.zeros((self.n, width + 1))
        gyro, accel = np.zeros((self.n, width + 1, 3)), np.zeros((self.n, width + 1, 3))
        uptime = np.full((self.n, width + 1), np.nan)
        row, distance = np.zeros((self.n, width + 1), np.intp), np.zeros((self.n, width + 1))
        status = np.zeros((self.n, width + 1), np.int64)
        for i, s in enumerate(streams):
            m = len(s.kind)
            kind[i, :m], t[i, :m], gyro[i, :m], accel[i, :m], uptime[i, :m] = \
                s.kind, s.t, s.gyro, s.accel, s.uptime
            row[i, :m], distance[i, :m], status[i, :m] = self.ranging.rows_of(s.anchor), s.distance, s.status
        at = np.zeros(self.n, np.int64)
        rows = np.arange(self.n)
        while True:
            live = rows[self._alive & (at < length)]
            if not live.size:
                break
            k = kind[live, at[live]]
            imu = live[k == IMU]
            if imu.size:
                j = at[imu]
                self._imu(imu, t[imu, j], gyro[imu, j], accel[imu, j], uptime[imu, j])
            exchanges = live[k == EXCHANGE]
            if exchanges.size:
                j = at[exchanges]
                self._exchanges(exchanges, t[exchanges, j], row[exchanges, j],
                                distance[exchanges, j], status[exchanges, j])
            timed = live[k == TIMED]
            if timed.size:
                self._timed(timed, t[timed, at[timed]])
            at[live] += 1
        return self._columns()

    def eject(self, idx: np.ndarray, why: str) -> None:
        """Seeds *idx* leave the batch (module doc): the caller runs them per seed."""
        for i in np.atleast_1d(idx).tolist():
            if self._alive[i]:
                self._alive[i] = False
                self.ejected[i] = why

    def alive(self, idx: np.ndarray) -> np.ndarray:
        """The seeds of *idx* still in the batch."""
        return idx[self._alive[idx]]

    # ---------------------------------------------------------------- records

    def _begin(self, idx: np.ndarray, t: np.ndarray) -> None:
        """Estimator.feed's first measurement: every clock starts, every track starts."""
        new = ~self.started[idx]
        if not new.any():
            return
        s, ts = idx[new], t[new]
        self.started[s] = True
        self.t[s] = self.t_first[s] = ts
        self.k_out[s] = np.ceil(ts / self.cfg.output_period_s).astype(np.int64)
        self.next_out[s] = self.k_out[s] * self.cfg.output_period_s
        for track in self.tracks:
            track.start(s, ts)

    def _imu(self, idx, t, gyro, accel, uptime) -> None:
        """Estimator.feed of one ImuSample per seed (Inertial.accept, step, motion)."""
        first = np.isnan(self.t_power_up[idx]) & ~np.isnan(uptime)
        if first.any():  # Inertial._power_up: within the alignment, it counts from there
            up = uptime[first]
            within = (0.0 <= up) & (up < self.cfg.alignment_s)
            self.t_power_up[idx[first][within]] = t[first][within] - up[within]
        self._begin(idx, t)
        self._emit(idx, t, through=False)
        self.t[idx] = np.fmax(self.t[idx], t)
        # Inertial.step
        unset = np.isnan(self.t_power_up[idx])
        self.t_power_up[idx[unset]] = t[unset]
        waiting = ~self.aligned[idx]
        aligning = waiting & ((not self.need_sins) | (t - self.t_power_up[idx] < self.cfg.alignment_s)
                              | ~self.has_last[idx])
        if aligning.any():
            a = idx[aligning]
            self.align_n[a] += 1
            self.align_gyro[a] += gyro[aligning]
            self.align_accel[a] += accel[aligning]
            self.last[a] = np.column_stack((gyro[aligning], accel[aligning]))
            self.has_last[a] = True
        starting = waiting & ~aligning
        if starting.any():
            self._start_strapdown(idx[starting])
        moving = ~aligning
        acceleration = None
        if moving.any():
            acceleration = self._step(idx, t, gyro, accel, moving)
        self.t_imu[idx] = t
        if Motion in self._takers:
            if self._ca:
                self._sync(idx, t)
            if aligning.any():
                a = idx[aligning]
                self._give(Motion, a, MotionBatch("stationary", t[aligning], np.zeros((len(a), 4)),
                                                  self._r_stationary, STATIONARY))
            if moving.any():
                m = idx[moving]
                T = t[moving] - self.t_aligned[m]
                R = (self._accel_var + self._tilt_growth * T * T)[:, None, None] * np.eye(2)
                self._give(Motion, m, MotionBatch("accel", t[moving], acceleration, R, ACCELERATION))
        self._give(ImuSample, idx, ImuBatch(t, gyro, accel))
        self._emit(idx, t, through=True)

    def _step(self, idx, t, gyro, accel, moving) -> np.ndarray:
        """Strapdown.step of the seeds *idx* whose strapdown is ``moving``, and of the tracks'
        own that step with the sample (BatchTrack.own_step), in one call; the estimator's
        horizontal dv/dt (host.batch.strapdown)."""
        m = idx[moving]
        rows, dt, of = [m], [t[moving] - self.t_imu[m]], [np.flatnonzero(moving)]
        for k, track in enumerate(self._owners, 1):
            on, own_dt = track.own_step(idx, t)
            rows.append(idx[on] + k * self.n)
            dt.append(own_dt)
            of.append(np.flatnonzero(on))
        if len(rows) > 1:
            of = np.concatenate(of)
            return self._strapdowns.step(np.concatenate(rows), np.concatenate(dt), gyro[of],
                                         accel[of])[:len(m)]
        return self._strapdowns.step(m, dt[0], gyro[moving], accel[moving])

    def _sync(self, idx, t) -> None:
        """FusionTrack.sync of every constant-acceleration track's seeds *idx* that take the
        Motion at t (its _update leaves a late one out), in one call."""
        idx = idx[self.t[idx] - t <= self.cfg.max_lag_s]
        rows = np.concatenate([idx + k * self.n for k in range(len(self._ca))])
        to = np.tile(self.t[idx], len(self._ca))
        behind = self._ca_t[rows] < to
        if behind.any():
            b, to = whole(rows[behind], len(self._ca_t)), to[behind]
            self._ca_x[b], self._ca_P[b] = propagate(self._ca_x[b], self._ca_P[b],
                                                     *self.model.many(to - self._ca_t[b]))
            self._ca_t[b] = to

    def _start_strapdown(self, idx: np.ndarray) -> None:
        """Inertial._start_strapdown for the seeds *idx*: the alignment's result (per seed:
        once a run), the strapdown at the origin, the last aligning sample recorded."""
        c = self.cfg
        q, bias = np.zeros((len(idx), 4)), np.zeros((len(idx), 3))
        for k, i in enumerate(idx.tolist()):
            a = Alignment.of(int(self.align_n[i]), self.align_gyro[i], self.align_accel[i]).result(
                c.heading_rad, math.radians(c.latitude_deg), c.x_azimuth_deg)
            q[k], bias[k] = a.q, a.gyro_bias
        self.sins.begin(idx, np.tile(np.asarray(c.start, float), (len(idx), 1)), q, bias)
        self.sins.step(idx, np.zeros(len(idx)), self.last[idx, :3], self.last[idx, 3:])
        self.t_aligned[idx] = self.t_imu[idx]
        self.aligned[idx] = True

    def _exchanges(self, idx, t, row, reported, status) -> None:
        """Estimator.feed of one Exchange per seed (its anchor's row, -1: unknown; its
        reported distance, NaN: none): the ranging (host.batch.ranging), the time base and
        the products, batched."""
        ranging = self.ranging
        taken = ranging.accept(row, t)
        if not taken.all():
            idx, t, row, reported, status = idx[taken], t[taken], row[taken], reported[taken], status[taken]
        if not idx.size:
            return
        self._begin(idx, t)
        self._emit(idx, t, through=False)
        self.t[idx] = np.fmax(self.t[idx], t)
        d = ranging.distance(row, reported, status)
        if Range in self._takers:  # Estimator._exchange: each distance, before its cycle
            has = ~np.isnan(d)
            if has.any():
                self._give(Range, idx[has], RangeBatch(t[has], d[has], row[has],
                                                       np.maximum(self.t[idx[has]] - t[has], 0.0)))
        c = ranging.add(idx, row, t, d)
        if c.idx.size:  # Estimator._cycle: the fix or why none, then the Tdoa
            fixed, p, cov, refused = ranging.fix(c)
            if refused:
                self._give(FixRefused, c.idx[list(refused)], list(refused.values()))
            if fixed.any():
                s = c.idx[fixed]
                self._give(Fix, s, FixBatch(c.t[fixed], p[fixed], cov[fixed], ranging.fixes[s]))
            if Tdoa in self._takers:
                for j, batch in ranging.tdoa(c, fixed, self.t[c.idx]):
                    self._give(Tdoa, c.idx[j], batch)
        self._emit(idx, t, through=True)

    def _timed(self, idx: np.ndarray, t: np.ndarray) -> None:
        """Estimator.feed of a record only tracks run per seed take: the time moves."""
        self._begin(idx, t)
        self._emit(idx, t, through=False)
        self.t[idx] = np.fmax(self.t[idx], t)
        self._emit(idx, t, through=True)

    def takes(self) -> frozenset:
        """The record and product types some batch track takes."""
        return frozenset(self._takers)

    def _give(self, kind: type, idx: np.ndarray, batch) -> None:
        for take in self._takers.get(kind, ()):
            take(idx, batch)

    # ---------------------------------------------------------------- time

    def stale(self, idx: np.ndarray, b: np.ndarray, t_aided: np.ndarray) -> np.ndarray:
        """FilterTime.stale: NaN in *t_aided* is never aided (the first measurement counts)."""
        since = np.where(np.isnan(t_aided), self.t_first[idx], t_aided)
        return b - since > self.cfg.extrapolated_after_s

    def _emit(self, idx: np.ndarray, t: np.ndarray, through: bool, upto=None) -> None:
        """Estimator._emit: the output instants before t (``through``: up to t) of each seed."""
        while idx.size:
            b = self.next_out[idx]
            due = (b < t) | (b == t) if through else b < t
            if not due.any():
                return
            idx, t, b = idx[due], t[due], b[due]
            yaw = np.full(len(idx), self.cfg.heading_rad)
            on = self.aligned[idx]
            if on.any():
                yaw[on] = self.sins.yaw(idx[on])
            for track in self.tracks:
                c = track.estimate(idx, b)
                bad = c.valid & ~np.isfinite(c.x.sum(1) + c.v.sum(1))
                if bad.any():
                    self.eject(idx[bad], f"{track.name}: estimate not finite")
                self._out[track.name].append(_rows(idx, b, c, yaw))
            self.k_out[idx] += 1
            self.next_out[idx] = self.k_out[idx] * self.cfg.output_period_s

    # ---------------------------------------------------------------- output

    def _columns(self) -> list[dict]:
        """Per seed, per track: t, x, y, vx, vy, yaw (NaN: none), cov (k, 16), extrapolated."""
        out: list[dict] = [{} for _ in range(self.n)]
        for name, chunks in self._out.items():
            if not chunks:
                continue
            seed, *cols = (np.concatenate(c) for c in zip(*chunks))
            order = np.argsort(seed, kind="stable")
            cols = dict(zip(COLUMNS, (c[order] for c in cols)))
            cuts = np.searchsorted(seed[order], np.arange(self.n + 1))
            for i in range(self.n):
                if self._alive[i]:
                    out[i][name] = {k: v[cuts[i]:cuts[i + 1]] for k, v in cols.items()}
        return out


def _rows(idx, b, c, yaw) -> tuple:
    """The output rows of one emit (seed, then :data:`COLUMNS`), the
    valid ones copied out: a view would keep the track's whole state (an 11- or 15-state P)
    alive until the run ends, megabytes a seed."""
    v = c.valid
    y = ((yaw if c.yaw is None else c.yaw) if c.has_yaw else np.full(len(b), np.nan))[v]
    return (idx[v], b[v], c.x[v, 0], c.x[v, 1], c.v[v, 0], c.v[v, 1], y,
            c.cov[v].reshape(-1, 16), c.stale[v])
