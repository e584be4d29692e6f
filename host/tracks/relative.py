"""What 004's tracks share (kf-rel, hinf, hinf+lssvm, hinf+bp): a filter of the INS's
*relative* errors (004 sect. 2.1) closed around a strapdown of their own.

State and measurement (004 eqs. 2.1-2.6)::

    X_k = (e_x, e_y, e_vx, e_vy)         the INS's position and velocity errors (INS - true)
    X_k+1 = A X_k + B w_k,  A = [[I, T I], [0, I]]                               (2.1, 2.4)
    Y_k = X_k + D v_k,      Y = (r_INS - r_WSN, v_INS - v_WSN)                   (2.5, 2.6)

T is the WSN's period (``period_s``, else ``cycle_s``; 004's 1 s). r_WSN is the cycle's WSN fix (at the mean
time of its exchanges); v_WSN the fixes' mean velocity over the period, (r_k - r_k-1) /
(t_k - t_k-1), and v_INS the INS's own mean over the same interval, so that the velocity
difference carries no lag when the vehicle accelerates. A fix older than ``outage_after_s``
has no velocity: it only starts the next period.

Time. A cycle's fix reaches the track when the cycle closes (host.wsn.CycleGrouper: at the
next cycle's first exchange, up to a period after the fix's time), so the track keeps its
strapdown's recent positions and velocities (at the IMU rate, ``outage_after_s`` + 2 T of
them) and compares each fix with the INS at the fix's own time. A correction estimated for
time t_k is carried to the present by the error model: position by c_p + (t - t_k) c_v,
velocity by c_v, in the strapdown and in the kept history from t_k on, which first gets a
state at t_k itself: the next update measures the INS's increments from there, and a state
interpolated across t_k would carry part of the correction into the velocity measured over
the period (at a 0.1 s period, up to 10 x the position correction: the loop diverges).

Closed loop. Each update's estimate of X_k is fed back into the strapdown (position and
velocity corrected, 004 sect. 4.1: "used to update the INS solution") and the state is zeroed,
so the prior of every update is X_k^- = A 0 = 0 and the filtered estimate is the gain
applied to the measured difference, X_k = K Y_k: the KF's gain (kf-rel) or the H-infinity
filter's (hinf; host.filters.hinf). The reported covariance is P propagated through the
same gain in Joseph form, P = (I - K) P^- (I - K)' + K R K' with P^- = A P A' + Q, under the
nominal noise Q = B B' (``ins_*_sigma``) and R = D D' (``wsn_*_sigma``): the KF's own, and
for the fixed H-infinity gain the covariance it gives if the noise is the nominal one.

Outages. Without a fix for ``outage_after_s`` (longer than the period plus the fix's
latency) the track is in an outage: the strapdown coasts, and a bridging track
(host.tracks.bridging) corrects it every period T from the last fix's time on, as the
filter would have. Each update's INS increments over its period (the change of position and
velocity between the two fixes' times, the corrections left out) are what a bridging model
is trained on against the update's correction.

Discontinuities (a device restart, an IMU gap): the track starts again at the next WSN fix
(at rest, ``reinit_sigma``), its attitude kept; after an IMU restart from the realigned
strapdown.
"""
from __future__ import annotations

from bisect import bisect_right
from collections import deque
from dataclasses import dataclass

import numpy as np

from navtwin.common.schema import key, positive
from navtwin.host.measurements import Fix, ImuSample

from .base import OwnStrapdown, Track, estimate


@dataclass(frozen=True)
class RelativeSettings:
    """004's noise scales: the diagonal of B (the INS's error growth per period) and of D (the
    WSN's position and velocity noise), the KF's Q and R, the H-infinity LMI's weights."""

    ins_position_sigma_m: float = key(0.05, "m", "INS position error growth per period, 1 sigma "
                                      "(B of 004 eq. 2.4)", positive(hi=1e4))
    ins_velocity_sigma_m_s: float = key(0.05, "m/s", "INS velocity error growth per period, 1 "
                                        "sigma (B of 004 eq. 2.4)", positive(hi=1e4))
    wsn_position_sigma_m: float = key(0.2, "m", "WSN fix error, 1 sigma (D of 004 eq. 2.6; "
                                      "004's 'about 20 cm')", positive(hi=1e4))
    wsn_velocity_sigma_m_s: float = key(0.3, "m/s", "WSN velocity error, 1 sigma: two fixes a "
                                        "period apart, sqrt(2) x 0.2 m / 1 s (D of 004 eq. 2.6)",
                                        positive(hi=1e4))
    period_s: float | None = key(None, "s", "the WSN's period T (004's 1 s); none = [filters] "
                                 "cycle_s (a shorter grouping window needs it)", positive(hi=3600))
    outage_after_s: float = key(2.5, "s", "no fix for this long: a WSN outage (the strapdown "
                                "coasts or is bridged); longer than the period and the fix's "
                                "latency (a period)", positive(hi=3600))

    @property
    def process(self) -> np.ndarray:
        s = self
        return np.array([s.ins_position_sigma_m] * 2 + [s.ins_velocity_sigma_m_s] * 2)

    @property
    def measurement(self) -> np.ndarray:
        s = self
        return np.array([s.wsn_position_sigma_m] * 2 + [s.wsn_velocity_sigma_m_s] * 2)


def transition(dt: float) -> np.ndarray:
    """A of 004 eq. 2.1 over dt."""
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    return A


class RelativeTrack(OwnStrapdown, Track):
    """The INS, the updates and the outages that 004's tracks share (module doc); a subclass
    gives :meth:`gain` (K for an update with prior covariance P^-)."""

    Settings = RelativeSettings
    uses_strapdown = True

    def __init__(self, ctx, settings=None) -> None:
        super().__init__(ctx, settings)
        s = self.settings
        self.T = float(s.period_s or ctx.cfg.cycle_s)
        self.Q = np.diag(s.process**2)
        self.R = np.diag(s.measurement**2)
        self.P = np.diag(s.measurement**2)
        self.t_P: float | None = None  # the time P is for
        self._aided: float | None = None
        self._last_fix: Fix | None = None
        self._keep_s = s.outage_after_s + 2.0 * self.T
        self._t: deque[float] = deque()  # the strapdown's recent states (module doc, "Time")
        self._pv: deque[np.ndarray] = deque()

    def gain(self, P_prior: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def handlers(self) -> dict:
        return {ImuSample: self.imu, Fix: self.fix}

    # -- life -------------------------------------------------------------------------------
    def restart(self, device: str, t: float) -> None:
        self.discontinuity("restart", t)
        self._last_fix = None
        if device == "imu":
            self.nav = None  # a new alignment gives the attitude
            self._t.clear()
            self._pv.clear()

    def gap(self, t: float) -> None:
        self.discontinuity("gap", t)
        self._last_fix = None

    def reinit_at(self, fix: Fix) -> bool:
        if self.nav is None:
            return False
        sv, _ = self.ctx.cfg.reinit_sigma
        self.nav.place(fix.p, (0.0, 0.0))
        self._t.clear()
        self._pv.clear()
        self._keep()
        self.P = np.diag([*np.diag(fix.cov), sv**2, sv**2])
        self.t_P = self._aided = fix.t
        self._last_fix = fix
        return True

    # -- the INS ----------------------------------------------------------------------------
    def _keep(self) -> None:
        nav, t = self.nav, self.t_nav
        self._t.append(t)
        self._pv.append(np.concatenate((nav.p[:2], nav.v[:2])))
        while t - self._t[0] > self._keep_s:
            self._t.popleft()
            self._pv.popleft()

    def ins_at(self, t: float) -> np.ndarray | None:
        """The strapdown's (x, y, vx, vy) at t, interpolated in its history (extrapolated at its
        velocity past the newest state); None when t is older than the history."""
        ts = self._t
        if not ts or t < ts[0]:
            return None
        k = bisect_right(ts, t)
        if k == len(ts):
            pv = self._pv[-1].copy()
            pv[:2] += (t - ts[-1]) * pv[2:]
            return pv
        t0, t1 = ts[k - 1], ts[k]
        w = (t - t0) / (t1 - t0)
        return (1.0 - w) * self._pv[k - 1] + w * self._pv[k]

    def correct(self, t_ref: float, c: np.ndarray) -> None:
        """Remove the errors c = (e_p, e_v) estimated at t_ref from the strapdown and from
        the history from t_ref on (module doc, "Time"). The history gets a state at t_ref
        itself, so the next update's INS at this fix's time is the corrected one: between two
        kept states it would mix in the uncorrected one before t_ref, and a velocity measured
        over a period of 0.1 s would take up to 10 x the position correction as its own error
        (the loop then diverges)."""
        cp, cv = c[:2], c[2:]
        k = bisect_right(self._t, t_ref)
        if 0 < k < len(self._t) and self._t[k - 1] != t_ref:
            self._pv.insert(k, self.ins_at(t_ref))
            self._t.insert(k, t_ref)
        self.nav.correct(cp + (self.t_nav - t_ref) * cv, cv, (0.0, 0.0, 0.0))
        for k in range(len(self._t) - 1, -1, -1):
            lag = self._t[k] - t_ref
            if lag < 0.0:
                break
            pv = self._pv[k]
            pv[:2] -= cp + lag * cv
            pv[2:] -= cv

    def started(self, t: float) -> None:
        self.t_P = t
        sp, sv, _ = self.ctx.cfg.p0_sigma
        self.P = np.diag([sp**2, sp**2, sv**2, sv**2])
        self._keep()

    def stepped(self, t: float, dt: float) -> None:
        self._keep()
        last = self._last_fix
        if last is not None and t - last.t > self.settings.outage_after_s and not self.pending:
            self.coast(t)

    def coast(self, t: float) -> None:
        """In an outage at t (no fix for ``outage_after_s``): the strapdown coasts."""

    # -- updates ----------------------------------------------------------------------------
    def fix(self, fix: Fix) -> None:
        if fix is self.reinit_fix or self.nav is None or self.pending:
            return
        now, last = self.ins_at(fix.t), self._last_fix
        if now is None:
            self.rejections["late"] += 1
            return
        before = None if last is None or fix.t - last.t > self.settings.outage_after_s \
            else self.ins_at(last.t)
        self._last_fix = fix
        if before is None or fix.t <= last.t:  # no velocity yet: this fix starts the next period
            self.rejections["no_velocity"] += 1
            return
        dt = fix.t - last.t
        moved = now - before  # the INS's own increments over the period (dp, dv)
        Y = np.concatenate((now[:2] - fix.p, (moved[:2] - (fix.p - last.p)) / dt))
        A = transition(fix.t - self.t_P)
        P_prior = A.dot(self.P).dot(A.T) + self.Q * ((fix.t - self.t_P) / self.T)
        K = self.gain(P_prior)
        c = K.dot(Y)
        IK = np.eye(4) - K
        self.P = IK.dot(P_prior).dot(IK.T) + K.dot(self.R).dot(K.T)
        self.t_P = self._aided = fix.t
        self.correct(fix.t, c)
        self.updates["fix"] += 1
        self.trained(moved, c)

    def trained(self, moved: np.ndarray, correction: np.ndarray) -> None:
        """An update corrected the INS by *correction* after it moved by *moved* (dp, dv)."""

    # -- output -----------------------------------------------------------------------------
    def estimate(self, b: float, yaw: float):
        if self.nav is None:
            return self.unstarted(b, yaw)
        lead = b - self.t_nav
        p, v = self.nav.p[:2] + lead * self.nav.v[:2], self.nav.v[:2]
        span = b - self.t_P
        A = transition(span)
        cov = A.dot(self.P).dot(A.T) + self.Q * (max(span, 0.0) / self.T)
        return estimate(b, self.name, p, v, self.nav.yaw, cov, self.pending or self.ctx.stale(b, self._aided))


class KfRelTrack(RelativeTrack):
    """``kf-rel``: 004's KF baseline: the Kalman gain K = P^- (P^- + R)^-1 on the relative
    error model (C = I), Q and R the nominal noise (module doc)."""

    name = "kf-rel"

    def gain(self, P_prior: np.ndarray) -> np.ndarray:
        return np.linalg.solve((P_prior + self.R).T, P_prior.T).T
