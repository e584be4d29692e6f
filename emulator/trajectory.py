"""The vehicle's true motion: a taped line with smooth turns, driven with a smooth speed.

Path. The waypoints are the corners of a polyline. Each corner with deflection D is
rounded by a clothoid (curvature 0 -> 1/R over ``transition_m``), a circular arc of radius R
and a clothoid back to 0, the standard road-design transition, so the curvature k(s) is
continuous and piecewise linear in arc length s. The curve leaves the incoming leg at the
tangent distance T = (R + p) tan(|D|/2) + k before the corner, where p and k are the shift and
abscissa of the clothoid's end (Fresnel integrals); with too little room for the clothoids,
they meet in the middle (no arc). Heading psi(s) = psi0 + k0 u + c u^2/2 within a piece; the
position is the exact integral of exp(i psi) (Fresnel integrals for the clothoids), so a
closed loop closes exactly and its laps repeat.

Speed. At rest for ``alignment_s``; then v = V (3x^2 - 2x^3), x = time / T_r over a ramp of
T_r = 1.5 V / a_peak (continuous acceleration, peak a_peak); cruise; the mirror ramp stops
the vehicle at the end of the last lap, where it stays. With ``step_m`` (001's calibration
walk) it moves instead step by step, resting ``dwell_s`` after each move (SteppedProfile).

Kinematics in the navigation frame (x, y the area's, z up; see emulator.scenario):
velocity v t, acceleration (dv/dt) t + k v^2 n (t tangent, n its left normal), yaw = psi,
level (roll = pitch = 0), body angular rate (0, 0, k v). All are continuous in time.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navtwin.common.schema import Invalid
from navtwin.emulator.fresnel import fresnel

TWO_PI = 2.0 * math.pi


def wrap(angle):
    """Angle(s) wrapped to (-pi, pi]."""
    return -((-np.asarray(angle) + math.pi) % TWO_PI - math.pi)


def _chord(psi0, k0, c, u):
    """Complex displacement integral_0^u exp(i (psi0 + k0 v + c v^2 / 2)) dv, elementwise."""
    psi0, k0, c, u = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (psi0, k0, c, u)))
    out = np.empty(u.shape, dtype=complex)
    line = (c == 0) & (k0 == 0)
    out[line] = u[line] * np.exp(1j * psi0[line])
    arc = (c == 0) & (k0 != 0)
    if arc.any():
        p, k, uu = psi0[arc], k0[arc], u[arc]
        out[arc] = (np.exp(1j * (p + k * uu)) - np.exp(1j * p)) / (1j * k)
    spiral = c != 0
    if spiral.any():
        p, k, cc, uu = psi0[spiral], k0[spiral], c[spiral], u[spiral]
        b = k / cc  # psi = psi0 - c b^2 / 2 + c (v + b)^2 / 2
        scale = np.sqrt(math.pi / np.abs(cc))
        s0, c0 = fresnel(b / scale)
        s1, c1 = fresnel((uu + b) / scale)
        e = (c1 - c0) + 1j * (s1 - s0)
        e = np.where(cc > 0, e, np.conj(e))
        out[spiral] = np.exp(1j * (p - cc * b * b / 2)) * scale * e
    return out


class _Corner(NamedTuple):
    tangent: float  # distance from the corner to where the curve leaves each leg
    pieces: list  # (length, k0, c) of clothoid, arc, clothoid


def _corner(deflection: float, radius: float, transition: float) -> _Corner:
    if abs(deflection) < 1e-12:
        return _Corner(0.0, [])
    sign = 1.0 if deflection > 0 else -1.0
    d = abs(deflection)
    theta = transition / (2 * radius)  # heading change along one clothoid
    length = transition
    if 2 * theta > d:  # no room for an arc: two clothoids meeting at curvature 1/radius' < 1/R
        theta = d / 2
        length = transition  # keep the transition, lower the peak curvature
        radius = length / (2 * theta)
    arc = d - 2 * theta
    if length > 0:
        end = _chord(0.0, 0.0, 1.0 / (radius * length), length)[()]
        p = end.imag - radius * (1 - math.cos(theta))
        k = end.real - radius * math.sin(theta)
    else:
        p = k = 0.0
    tangent = (radius + p) * math.tan(d / 2) + k
    kappa = sign / radius
    pieces = []
    if length > 0:
        pieces.append((length, 0.0, kappa / length))
    if arc > 0:
        pieces.append((radius * arc, kappa, 0.0))
    if length > 0:
        pieces.append((length, kappa, -kappa / length))
    return _Corner(tangent, pieces)


class Path:
    """The taped line as pieces of linear curvature, evaluated by arc length."""

    def __init__(self, waypoints, closed: bool, turn_radius: float, transition: float) -> None:
        pts = [complex(x, y) for x, y in waypoints]
        if closed:
            pts.append(pts[0])
        legs = [b - a for a, b in zip(pts, pts[1:])]
        headings = [math.atan2(v.imag, v.real) for v in legs]
        n_legs = len(legs)
        # corner j sits at the end of leg j (closed: the last one is the start, straight)
        corners = []
        for j in range(n_legs - (0 if closed else 1)):
            nxt = headings[(j + 1) % n_legs]
            defl = float(wrap(nxt - headings[j]))
            if abs(defl) > math.radians(179):
                raise Invalid("waypoints", f"{(j + 1) % len(waypoints) + 1} turns back on itself; "
                                           "add a waypoint to turn in two steps")
            corners.append(_corner(defl, turn_radius, transition))
        pieces = []  # (length, k0, c)
        for j, leg in enumerate(legs):
            before = corners[j - 1].tangent if (j > 0 or closed) else 0.0
            after = corners[j].tangent if j < len(corners) else 0.0
            straight = abs(leg) - before - after
            if straight < -1e-9:
                raise Invalid("turn_radius_m", f"{turn_radius:g} m (with transition_m {transition:g} m) "
                                               f"does not fit leg {j + 1}: the turns need "
                                               f"{before + after:.2f} m of its {abs(leg):.2f} m; "
                                               "use a smaller turn radius or move the waypoints apart")
            if straight > 0:
                pieces.append((straight, 0.0, 0.0))
            if j < len(corners):
                pieces.extend(corners[j].pieces)
        lengths = np.array([p[0] for p in pieces])
        self.k0 = np.array([p[1] for p in pieces])
        self.c = np.array([p[2] for p in pieces])
        self.s0 = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))
        self.length = float(lengths.sum())
        self.closed = closed
        self.psi0 = np.empty(len(pieces))
        self.p0 = np.empty(len(pieces), dtype=complex)
        psi, p = headings[0], pts[0]
        for i in range(len(pieces)):
            self.psi0[i], self.p0[i] = psi, p
            p = p + _chord(psi, self.k0[i], self.c[i], lengths[i])[()]
            psi += self.k0[i] * lengths[i] + self.c[i] * lengths[i] ** 2 / 2
        self.end_heading = psi
        self.end = p

    def evaluate(self, s):
        """(position as complex x + iy, heading psi, curvature k) at arc length(s) *s*,
        taken modulo the lap for a closed loop and clamped to [0, length] otherwise."""
        s = np.asarray(s, dtype=float)
        s = np.mod(s, self.length) if self.closed else np.clip(s, 0.0, self.length)
        i = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)
        u = s - self.s0[i]
        k0, c, psi0 = self.k0[i], self.c[i], self.psi0[i]
        pos = self.p0[i] + _chord(psi0, k0, c, u)
        return pos, psi0 + k0 * u + c * u * u / 2, k0 + c * u


class SpeedProfile:
    """Distance, speed and tangential acceleration over time: rest, smooth ramp, cruise,
    smooth ramp down to rest at *distance*."""

    def __init__(self, alignment_s: float, speed: float, accel: float, distance: float) -> None:
        self.v = speed
        self.ramp = 1.5 * speed / accel  # smoothstep peak acceleration = 1.5 V / T_r
        ramp_distance = speed * self.ramp / 2
        if distance < 2 * ramp_distance:
            raise Invalid("speed_m_s", f"{speed:g} m/s cannot be reached and stopped within the "
                                       f"{distance:.2f} m path at accel_m_s2 {accel:g} (needs "
                                       f"{2 * ramp_distance:.2f} m); lower the speed or raise the acceleration")
        self.t1 = alignment_s
        self.t2 = self.t1 + self.ramp
        self.t3 = self.t2 + (distance - 2 * ramp_distance) / speed
        self.t4 = self.t3 + self.ramp
        self.distance = distance
        self.ramp_distance = ramp_distance

    def evaluate(self, t):
        """(s, v, dv/dt) at true time(s) *t* in seconds (1-D array)."""
        t = np.asarray(t, dtype=float)
        v_max, tr = self.v, self.ramp
        s, v, a = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
        phase = np.searchsorted((self.t1, self.t2, self.t3, self.t4), t, side="right")
        phases = np.unique(phase).tolist()
        for p in phases:  # rest, ramp up, cruise, ramp down, stopped
            at = slice(None) if len(phases) == 1 else phase == p
            tp = t[at]
            if p == 1:
                x = (tp - self.t1) / tr
                s[at] = v_max * tr * (x ** 3 - x ** 4 / 2)
                v[at] = v_max * (3 * x ** 2 - 2 * x ** 3)
                a[at] = 6 * v_max / tr * x * (1 - x)
            elif p == 2:
                s[at] = self.ramp_distance + v_max * (tp - self.t2)
                v[at] = v_max
            elif p == 3:
                y = (tp - self.t3) / tr
                s[at] = self.distance - self.ramp_distance + v_max * tr * (y - y ** 3 + y ** 4 / 2)
                v[at] = v_max * (1 - 3 * y ** 2 + 2 * y ** 3)
                a[at] = -6 * v_max / tr * y * (1 - y)
            elif p == 4:
                s[at] = self.distance
        return s, v, a


class SteppedProfile:
    """001 sect. 3.3's calibration walk: at rest for *alignment_s*, then moves of *step* m,
    each a minimum-jerk move s = step (10 x^3 - 15 x^4 + 6 x^5), x = time / T (speed and
    acceleration continuous, zero at both ends; peak speed 1.875 step / T, peak acceleration
    5.7735 step / T^2, T the shortest that keeps both within *speed* and *accel*), each
    followed by *dwell* s at rest; the last move may be shorter, so the walk ends at
    *distance*."""

    PEAK_V, PEAK_A = 1.875, 10.0 / math.sqrt(3.0)  # of the unit move over unit time

    def __init__(self, alignment_s: float, speed: float, accel: float, distance: float,
                 step: float, dwell: float) -> None:
        self.t1, self.step, self.dwell, self.distance = alignment_s, step, dwell, distance
        self.moves = max(1, math.ceil(distance / step - 1e-9))
        self.move_s = max(self.PEAK_V * step / speed, math.sqrt(self.PEAK_A * step / accel))
        self.period = self.move_s + dwell
        self.t4 = alignment_s + (self.moves - 1) * self.period + self.move_s  # at rest for good

    def rests(self) -> list[tuple[float, float, float]]:
        """(from s, to s, arc length) of each rest: the alignment, then after every move
        (the last lasts for ever: to = inf)."""
        out = [(0.0, self.t1, 0.0)]
        for k in range(self.moves):
            start = self.t1 + k * self.period + self.move_s
            end = start + self.dwell if k < self.moves - 1 else math.inf
            out.append((start, end, min((k + 1) * self.step, self.distance)))
        return out

    def evaluate(self, t):
        """(s, v, dv/dt) at true time(s) *t* in seconds (1-D array)."""
        t = np.asarray(t, dtype=float)
        k = np.clip(np.floor((t - self.t1) / self.period), 0, self.moves - 1)
        length = np.minimum(self.step, self.distance - k * self.step)  # this move's
        x = np.clip((t - self.t1 - k * self.period) / self.move_s, 0.0, 1.0)
        x = np.where(t < self.t1, 0.0, x)
        tm = self.move_s
        s = k * self.step + length * x ** 3 * (10 - 15 * x + 6 * x * x)
        v = length / tm * 30 * x * x * (1 - x) ** 2
        a = length / tm ** 2 * 60 * x * (1 - x) * (1 - 2 * x)
        return s, v, a


class Kinematics(NamedTuple):
    """True state at some instants, navigation frame (x, y area, z up); rates in body axes."""

    pos: np.ndarray  # (N, 3) m
    vel: np.ndarray  # (N, 3) m/s
    acc: np.ndarray  # (N, 3) m/s^2, kinematic (not specific force)
    roll: np.ndarray  # rad
    pitch: np.ndarray  # rad
    yaw: np.ndarray  # rad, wrapped to (-pi, pi], 0 = body x along +x, counter-clockwise
    rate: np.ndarray  # (N, 3) rad/s, body angular rate relative to the navigation frame


class Trajectory:
    """The vehicle of a scenario: ``Trajectory(sc.trajectory, height=sc.tag.z)``."""

    def __init__(self, spec, height: float) -> None:
        self.key = (spec, height)  # all its motion depends on
        self.path = Path(spec.waypoints, spec.closed, spec.turn_radius_m, spec.transition_m)
        distance = self.path.length * spec.loops
        self.speed = SteppedProfile(spec.alignment_s, spec.speed_m_s, spec.accel_m_s2, distance,
                                    spec.step_m, spec.dwell_s) if spec.step_m else \
            SpeedProfile(spec.alignment_s, spec.speed_m_s, spec.accel_m_s2, distance)
        self.height = height

    def kinematics(self, t_ns) -> Kinematics:
        """True kinematics at true time(s) *t_ns* (integer ns, array)."""
        t = np.asarray(t_ns, dtype=np.int64) / 1e9
        s, v, at = self.speed.evaluate(t)
        pos_c, psi, kappa = self.path.evaluate(s)
        tangent = np.exp(1j * psi)
        vel_c = v * tangent
        acc_c = at * tangent + kappa * v * v * 1j * tangent
        n = t.shape[0] if t.ndim else 1
        zeros = np.zeros(n)
        return Kinematics(
            pos=np.column_stack((pos_c.real, pos_c.imag, np.full(n, self.height))),
            vel=np.column_stack((vel_c.real, vel_c.imag, zeros)),
            acc=np.column_stack((acc_c.real, acc_c.imag, zeros)),
            roll=zeros, pitch=zeros.copy(), yaw=wrap(psi),
            rate=np.column_stack((zeros, zeros, kappa * v)),
        )

    def position(self, t_ns) -> np.ndarray:
        """(N, 3) true positions only (cheaper: for ranging)."""
        s, _, _ = self.speed.evaluate(np.asarray(t_ns, dtype=np.int64) / 1e9)
        pos_c = self.path.evaluate(s)[0]
        return np.column_stack((pos_c.real, pos_c.imag, np.full(pos_c.shape, self.height)))
