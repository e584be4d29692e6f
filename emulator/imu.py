"""ADIS16350 model: true motion -> internal samples -> Bartlett filter -> output registers.

Physics in the local-level frame n at the vehicle's current geodetic point (x, y the area's
axes, +x at its azimuth A, z up; body b: x forward, y left, z up)::

    f_b  = C_bn (a_n + (2 w_ie + w_en) x v_n - g_n),   g_n = (0, 0, -g_local)   (000 sect. 3.1)
    w_ib = w_nb + C_bn (w_ie + w_en)
    w_ie = W (0, cos L, sin L)                                      ENU, W = 7.2916e-5 rad/s
    w_en = (-v_N / (R_M + h), v_E / (R_N + h), v_E tan L / (R_N + h))   ENU (transport rate)

with L, h the latitude and height of the vehicle's point (its place in the area's tangent
plane through common.geodesy), R_M, R_N the WGS-84 radii there, rotated from ENU to the
area's axes by A. The truth's roll, pitch and yaw are relative to that local level. Gravity
is the scenario's local_gravity along the local down: its change over an area is far below
the accelerometers' 0.7 mg floor (0.74 ug per km north at 32 deg N; 0.31 ug per m of
height, 0.06 ug at the plane's 0.18 m above the ellipsoid 1.5 km out), so it is left out
(docs/emulator-models.md 2.1).
Each internal sample j (every SMPL_PRD period of the sensor's own clock, 819.2 SPS by
default) is measured as::

    y_j = M x_j + b_on + b_j + n_j           then clipped to the selected range

with the errors of the scenario's IMU grade (emulator.imu_errors; ``[imu] grade``):
M = I + diag(scale-factor errors) + off-diagonal misalignment (drawn at power-on);
b_on the constant bias (drawn at power-on); b_j the in-run bias: a first-order Gauss-Markov
process b_{j+1} = phi b_j + sigma sqrt(1 - phi^2) w_j, phi = exp(-Ts / tau), started
stationary (a grade with a bias correlation time tau: sigma = its bias instability), or a
flicker bias with a flat Allan floor (tau = 0; emulator.bias), plus a rate random walk if the
grade has one; n_j white with sigma = ARW sqrt(fs) (gyro, ARW in rad/sqrt(s)) or
VRW sqrt(fs) (accelerometer). Temperature and supply are
measured with the sample (scenario value plus white noise). The output registers hold the
Bartlett-window FIR of the last samples: two cascaded N-tap averages (datasheet p. 17,
H(f) = [sin(pi N f ts) / (N sin(pi f ts))]^2, N = 2^SENS/AVG[2:0]). A read returns the
registers of the latest sample, quantised to 14 bits (gyro, accelerometer; 32 bits with
``[imu] words = "adis16488"``, emulator.imu_words) or 12 bits (temperature, supply) with
ND = 1 when a sample arrived since the previous read and EA = 1 while a STATUS flag is set (overrange of the read sample; supply outside 4.75..5.25 V).
Datasheet figures: shared/reference/adis16350-nanoloc-facts.md section 1.4.
"""
from __future__ import annotations

import contextlib
import math
import threading

import numpy as np

from navtwin.common.earth import EARTH_RATE
from navtwin.common.geodesy import LocalFrame, meridian_radius, transverse_radius
from navtwin.protocols import adis16350 as adis

from .alike import alike
from .bias import FlickerBias, RateRandomWalk
from .clock import Clock

#: per thread, while :func:`shared_truth` is entered: ``shared``, the error-free outputs of
#: every block made, by the sensor's motion and the block's sample times
_LOCAL = threading.local()
SHARED_BLOCKS = 1024  # at most this many blocks kept (about 40 kB each): then it starts over


def _shared() -> dict | None:
    return getattr(_LOCAL, "shared", None)


@contextlib.contextmanager
def shared_truth():
    """Within it (in this thread), sensors that move alike (the same trajectory, height, site
    and area) and sample at the same true times share their error-free outputs
    (:meth:`Adis16350.true_outputs`): the seeds of one scenario, made one after another (a
    sweep's task), compute each block's kinematics once. The outputs are a function of
    those inputs alone, so every byte is the same; the arrays are read-only. The vehicles'
    truth for evaluation is shared so too (lab.run.truth)."""
    outer = _shared()
    _LOCAL.shared = {} if outer is None else outer
    try:
        yield
    finally:
        _LOCAL.shared = outer


def shared(key, make):
    """``make()``, a tuple of arrays or an array that is a function of *key* alone: within
    :func:`shared_truth` made once per key (read-only), else each time (*key* None: always)."""
    store = _shared()
    if store is None or key is None:
        return make()
    got = store.get(key)
    if got is None:
        if len(store) >= SHARED_BLOCKS:
            store.clear()
        got = store[key] = make()
        for a in got if isinstance(got, tuple) else (got,):
            a.flags.writeable = False
    return got


MG = 1e-3 * adis.STANDARD_GRAVITY  # m/s^2 per mg
SUPPLY_LIMITS_V = (4.75, 5.25)  # STATUS bits 0 and 1
#: samples between exact geodetic conversions of the vehicle's point (32 = 39 ms at 819.2 SPS)
GEODETIC_EVERY = 32


def deg_h(v: float) -> float:
    """deg/h -> rad/s (radians first: the figures of the golden recordings to the bit)."""
    return math.radians(v) / 3600.0


def ug(v: float) -> float:
    """micro-g -> m/s^2, through mg (the golden recordings' figures to the bit)."""
    return v / 1000.0 * MG


def fir_steady_state(taps: np.ndarray) -> np.ndarray:
    """The FIR's delays after a constant input of 1: delay i holds the sum of taps[i + 1:]."""
    return np.cumsum(taps[:0:-1])[::-1]


def fir(taps: np.ndarray, x: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The board's FIR over the samples x (N, 3) from the delays *state* (len(taps) - 1, 3):
    the filtered samples and the delays after them. Each column is one full convolution with
    the delays added to its head, as scipy's lfilter computes a FIR (the same bytes)."""
    full = np.empty((len(x) + len(taps) - 1, x.shape[1]))
    for k, column in enumerate(x.T):
        full[:, k] = np.convolve(taps, column)
    full[:len(state)] += state
    return full[:len(x)], full[len(x):]


def gauss_markov(phi: float, state: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """b_j = phi b_j-1 + steps_j down each column (N, 3), from phi b_-1 = *state*, in the order
    of operations of scipy's lfilter([1], [1, -phi]) that the golden recordings were made with.
    A recursion does not vectorise to the bit: one float operation per step (about 1 ms for a
    second of samples, nothing beside the emulator's other work)."""
    out = np.empty_like(steps)
    for axis, first in enumerate(state):
        column = steps[:, axis].tolist()
        b = column[0] = first + column[0]
        for j in range(1, len(column)):
            b = column[j] = phi * b + column[j]
        out[:, axis] = column
    return out


def body_from_nav(roll, pitch, yaw) -> np.ndarray:
    """(N, 3, 3) C_bn for Z-Y-X angles: C_nb = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    c_nb = np.empty((len(yaw), 3, 3))
    c_nb[:, 0] = np.column_stack((cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr))
    c_nb[:, 1] = np.column_stack((sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr))
    c_nb[:, 2] = np.column_stack((-sp, cp * sr, cp * cr))
    return c_nb.transpose(0, 2, 1)


class _Sensor:
    """One triad (gyros or accelerometers): power-on errors, bias processes, filter state.
    Power-on errors, white noise and a Gauss-Markov bias draw from the IMU's stream *rng*; a
    flicker bias and a rate random walk from the triad's own stream *drift_rng*, so a grade
    with them leaves every other draw where it was."""

    def __init__(self, rng: np.random.Generator, drift_rng: np.random.Generator, *, noise: float, bias: float,
                 corr_s: float, rrw: float, turn_on: float, scale_ppm: float, misalign_rad: float,
                 full_scale: float, ts: float, taps: np.ndarray) -> None:
        self.noise = noise
        self.full_scale = full_scale
        self.taps = taps
        self.turn_on = rng.normal(0.0, turn_on, 3)
        m = np.eye(3) + np.diag(rng.normal(0.0, scale_ppm * 1e-6, 3))
        off = ~np.eye(3, dtype=bool)
        m[off] = rng.normal(0.0, misalign_rad, 6)
        self.matrix = m
        gm_sigma = bias if corr_s > 0 else 0.0  # corr_s = 0: the bias is flicker, no GM term
        self.phi = math.exp(-ts / corr_s) if corr_s > 0 else 0.0
        self.drive = gm_sigma * math.sqrt(1.0 - self.phi ** 2)
        self.gm_state = self.phi * rng.normal(0.0, gm_sigma, 3)  # phi b_{-1}
        self.slow = [process for process in (
            FlickerBias(bias, ts, drift_rng) if corr_s == 0 and bias > 0 else None,
            RateRandomWalk(rrw, ts, drift_rng) if rrw > 0 else None) if process is not None]
        self.fir_state = None

    @staticmethod
    def measure(triads: list[_Sensor], true: np.ndarray, white: np.ndarray, drive: np.ndarray):
        """Filtered outputs (S, N, 3) and per-sample overrange flags (S, N) of the S *triads*
        (alike: one grade, one of each seed's sensors) for the true values (N, 3) they all
        sense, with their white noise and GM drive (S, N, 3). Each seed's arithmetic is
        what it would be alone (S = 1): the products stacked per seed, the rest elementwise."""
        first = triads[0]
        raw = np.matmul(true, np.stack([t.matrix for t in triads]).transpose(0, 2, 1)) \
            + np.stack([t.turn_on for t in triads])[:, None, :]
        if first.drive:
            for t, row, steps in zip(triads, raw, drive):
                gm = gauss_markov(t.phi, t.gm_state, t.drive * steps)
                t.gm_state = t.phi * gm[-1]
                row += gm
        for k, process in enumerate(first.slow):
            raw += type(process).together([t.slow[k] for t in triads], len(true))
        raw += first.noise * white
        over = np.abs(raw) > first.full_scale
        raw = np.clip(raw, -first.full_scale, first.full_scale)
        out = np.empty_like(raw)
        for t, row, filtered in zip(triads, raw, out):
            if t.fir_state is None:  # the sensor ran before t = 0: start from steady state,
                # each delay holding raw[0] times the taps it has still to add
                t.fir_state = fir_steady_state(t.taps)[:, None] * row[0]
            filtered[:], t.fir_state = fir(t.taps, row, t.fir_state)
        return out, over.any(axis=2)

    def errors(self) -> dict:
        return {"turn_on_bias": self.turn_on.tolist(), "matrix": self.matrix.tolist()}


class Adis16350:
    """The sensor on the vehicle. ``generate(lo, hi)`` runs the internal samples of a block of
    true time in order; ``read(t_read)`` returns the register words the DSP reads."""

    def __init__(self, spec, site, area, trajectory, ppm: float, streams) -> None:
        """*spec* an ``[imu]`` table; *streams(name)* the Generator named *name* of the run:
        "imu" for the power-on errors and the sample noise, "imu.gyro.drift" and
        "imu.accel.drift" for each triad's flicker bias and rate random walk."""
        self.spec = spec
        self.trajectory = trajectory
        self.rng = rng = streams("imu")
        e = spec.errors
        ts = spec.sample_period_s
        self.clock = Clock(ppm, ts * 1e9)
        fs = 1.0 / ts
        taps = adis.bartlett_taps(spec.filter_taps)
        self.words = spec.word_format
        self.gyro = _Sensor(
            rng, streams("imu.gyro.drift"),
            noise=math.radians(e.gyro_arw_deg_rt_h) / 60.0 * math.sqrt(fs),
            bias=deg_h(e.gyro_bias_instability_deg_h), corr_s=e.gyro_bias_corr_s,
            rrw=deg_h(e.gyro_rrw_deg_h_rt_h) / 60.0, turn_on=deg_h(e.gyro_bias_deg_h),
            scale_ppm=e.gyro_scale_factor_ppm, misalign_rad=e.gyro_misalignment_mrad / 1e3,
            full_scale=math.radians(self.words.gyro_range_dps(spec)), ts=ts, taps=taps)
        self.accel = _Sensor(
            rng, streams("imu.accel.drift"),
            noise=e.accel_vrw_m_s_rt_h / 60.0 * math.sqrt(fs),
            bias=ug(e.accel_bias_instability_ug), corr_s=e.accel_bias_corr_s,
            rrw=ug(e.accel_rrw_ug_rt_h) / 60.0, turn_on=ug(e.accel_bias_ug),
            scale_ppm=e.accel_scale_factor_ppm, misalign_rad=e.accel_misalignment_mrad / 1e3,
            full_scale=e.accel_range_g * adis.STANDARD_GRAVITY, ts=ts, taps=taps)
        self.frame = LocalFrame.of(site, area)
        # what true_outputs depends on but t (None: a motion without a key is never shared)
        key = getattr(trajectory, "key", None)
        self._motion = None if key is None else (key, site, area)
        a = math.radians(area.x_azimuth_deg)  # north is at A counter-clockwise from +x
        # rows: ENU -> the area's x, y, z (x = e sin A + n cos A, y = -e cos A + n sin A)
        self.enu_to_n = np.array([[math.sin(a), math.cos(a), 0.0], [-math.cos(a), math.sin(a), 0.0],
                                  [0.0, 0.0, 1.0]])
        self.gravity_n = np.array([0.0, 0.0, -site.local_gravity])
        # the samples of the previous and the current block (reads may reach back)
        self._t = np.empty(0, dtype=np.int64)
        self._j = np.empty(0, dtype=np.int64)
        self._gyro = np.empty((0, 3))
        self._accel = np.empty((0, 3))
        self._supply = np.empty(0)
        self._temp = np.empty((0, 3))
        self._alarm = np.empty(0, dtype=bool)  # some STATUS flag set at this sample
        self._last_read_j = -1
        self.made_ns = 0  # the blocks before it are run

    def frame_rates(self, pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) earth rate w_ie and transport rate w_en in the area's axes at local points
        *pos* moving at *vel* (module docstring). Latitude and height are converted exactly at
        every GEODETIC_EVERY-th point (and the last) and interpolated between: along a path
        whose acceleration is at most a, that is off by a dt^2 / (8 R) = 1.5e-11 rad at 0.5
        m/s^2 over 39 ms (the conversion is the costly part of the physics). The radii are
        taken at the first point's latitude: over one block (1 s) they change by 1e-9."""
        knots = np.unique(np.append(np.arange(0, len(pos), GEODETIC_EVERY), len(pos) - 1))
        lat_deg, _, h_knots = self.frame.geodetic(pos[knots])
        at = np.arange(len(pos))
        lat, h = np.interp(at, knots, np.radians(lat_deg)), np.interp(at, knots, h_knots)
        r_m, r_n = meridian_radius(lat[0]) + h, transverse_radius(lat[0]) + h
        v_enu = vel @ self.enu_to_n  # the inverse rotation: its transpose
        cos_l, sin_l = np.cos(lat), np.sin(lat)
        w_ie = EARTH_RATE * np.column_stack((np.zeros_like(lat), cos_l, sin_l))
        w_en = np.column_stack((-v_enu[:, 1] / r_m, v_enu[:, 0] / r_n, v_enu[:, 0] * sin_l / cos_l / r_n))
        return w_ie @ self.enu_to_n.T, w_en @ self.enu_to_n.T

    def true_outputs(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Error-free specific force (m/s^2) and angular rate (rad/s), body axes (within
        :func:`shared_truth`, computed once for sensors that move alike)."""
        return shared(None if self._motion is None else (self._motion, t_ns.tobytes()),
                      lambda: self._true_outputs(t_ns))

    def _true_outputs(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = self.trajectory.kinematics(t_ns)
        c_bn = body_from_nav(k.roll, k.pitch, k.yaw)
        w_ie, w_en = self.frame_rates(k.pos, k.vel)
        f_n = k.acc + np.cross(2.0 * w_ie + w_en, k.vel) - self.gravity_n
        f_b = np.einsum("nij,nj->ni", c_bn, f_n)
        w_b = k.rate + np.einsum("nij,nj->ni", c_bn, w_ie + w_en)
        return f_b, w_b

    def generate(self, lo_ns: int, hi_ns: int) -> None:
        """Run the internal samples with lo_ns <= t < hi_ns (blocks must follow each other;
        a block :func:`generate_together` ran already is not run again)."""
        if hi_ns > self.made_ns:
            generate_together([self], lo_ns, hi_ns)

    @property
    def key(self):
        """What :func:`generate_together` runs alike: sensors of equal key sample the same
        true outputs at the same times with the same grade, filter and words, from the same
        block on (another seed of the same vehicle); None: it runs alone."""
        if self._motion is None:
            return None
        return self._motion, self.spec, tuple(vars(self.clock).values()), self.made_ns

    def _latest(self, t_read_ns: np.ndarray) -> np.ndarray:
        """Index of the latest internal sample at each read time."""
        i = np.searchsorted(self._t, t_read_ns, side="right") - 1
        if len(i) and i[0] < 0:
            raise ValueError("read before the first internal sample")
        return i

    def outputs(self, t_read_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The gyro (rad/s) and accelerometer (m/s^2) registers a read at each time returns,
        before the words' quantisation (for evaluation: a grade finer than an LSB)."""
        i = self._latest(t_read_ns)
        return self._gyro[i], self._accel[i]

    def read(self, t_read_ns: np.ndarray) -> np.ndarray:
        """(M, 11) register words SUPPLY_OUT..AUX_ADC read at increasing true times, the
        gyro and accelerometer columns in the scenario's words (emulator.imu_words)."""
        return Adis16350.read_together([self], t_read_ns)[0]

    @staticmethod
    def read_together(sensors: list[Adis16350], t_read_ns: np.ndarray) -> np.ndarray:
        """(S, M, 11): :meth:`read` of each of S *sensors* of one :attr:`key` (their samples
        at the same times: a sweep's seeds), each one's words as alone."""
        first = sensors[0]
        i = first._latest(t_read_ns)
        j = first._j[i]
        last = np.array([[s._last_read_j] for s in sensors])
        nd = np.diff(np.concatenate((last, np.broadcast_to(j, (len(sensors), len(j)))), axis=1)) > 0
        if len(j):
            for s in sensors:
                s._last_read_j = int(j[-1])
        supply, temp, gyro, accel, ea = (np.stack([getattr(s, name)[i] for s in sensors])
                                         for name in ("_supply", "_temp", "_gyro", "_accel", "_alarm"))
        q, p = adis.quantise, adis.pack
        words = np.empty((len(sensors), len(i), 11), dtype=np.int64)
        words[..., 0] = p(q(supply, adis.SUPPLY_LSB_V), 12, nd=False, is_signed=False)
        words[..., 1:7] = first.words.inertial(gyro, accel, first.spec)
        words[..., 7:10] = p(q(temp - adis.TEMP_ZERO_C, adis.TEMP_LSB_C), 12, nd=False)
        words[..., 10] = p(q(np.zeros(len(i)), adis.AUX_LSB_V), 12, nd=False, is_signed=False)
        flags = np.where(nd, adis.ND, 0) | np.where(ea, adis.EA, 0)
        words[..., first.words.flagged] |= flags[..., None]
        return words

    def errors(self) -> dict:
        """The power-on draws (for evaluation; they never reach the host)."""
        return {"gyro": self.gyro.errors(), "accel": self.accel.errors()}


def generate_together(sensors: list[Adis16350], lo_ns: int, hi_ns: int) -> None:
    """:meth:`Adis16350.generate` of the block [lo_ns, hi_ns) for each of *sensors*, each
    sensor's samples and state as it alone would leave them: the sensors of one
    :attr:`~Adis16350.key` (a sweep's seeds of one vehicle) are run along a leading seed
    axis, so each numpy call of the model serves them all (every draw is still each seed's
    own, from its own streams, in its own order); the others one by one."""
    for members in alike([sensor.key for sensor in sensors]):
        _generate([sensors[i] for i in members], lo_ns, hi_ns)


def _generate(sensors: list[Adis16350], lo_ns: int, hi_ns: int) -> None:
    first = sensors[0]
    j = first.clock.ticks_between(lo_ns, hi_ns)
    for sensor in sensors:
        sensor.made_ns = hi_ns
    if not len(j):  # a short last block with no sample in it (a slow SMPL_PRD)
        return
    t = first.clock.tick(j)
    f_b, w_b = first.true_outputs(t)
    z = np.empty((len(sensors), len(j), 16))
    for sensor, draws in zip(sensors, z):  # each seed's draws, in its own order, in place
        sensor.rng.standard_normal(out=draws)
    gyro, gover = _Sensor.measure([s.gyro for s in sensors], w_b, z[..., 0:3], z[..., 3:6])
    accel, aover = _Sensor.measure([s.accel for s in sensors], f_b, z[..., 6:9], z[..., 9:12])
    spec = first.spec
    supply = spec.supply_v + spec.supply_noise_v * z[..., 12]
    temp = spec.temperature_c + spec.temperature_noise_c * z[..., 13:16]
    alarm = gover | aover | (supply < SUPPLY_LIMITS_V[0]) | (supply > SUPPLY_LIMITS_V[1])
    # one earlier block is plenty for any read; the sensors alike sample at the same times,
    # so they share those arrays (none is changed in place)
    cut = int(np.searchsorted(first._t, lo_ns - 1_000_000_000))
    times, ticks = np.concatenate((first._t[cut:], t)), np.concatenate((first._j[cut:], j))
    for k, sensor in enumerate(sensors):
        sensor._t, sensor._j = times, ticks
        for name, new in (("_gyro", gyro[k]), ("_accel", accel[k]), ("_supply", supply[k]),
                          ("_temp", temp[k]), ("_alarm", alarm[k])):
            setattr(sensor, name, np.concatenate((getattr(sensor, name)[cut:], new)))
