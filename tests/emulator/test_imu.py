"""ADIS16350 model, checked on the decoded SINS bytes: the datasheet's filter, the physics
at rest and in motion, the error budget of the integrated z gyro, and the register flags."""
import dataclasses
import functools
import math
import threading

import numpy as np
import pytest

from navtwin.common.earth import EARTH_RATE
from navtwin.common.geodesy import meridian_radius, transverse_radius
from navtwin.emulator.bias import FLICKER_TAUS_S, flicker_term_variance
from navtwin.emulator import imu
from navtwin.emulator.imu import (Adis16350, deg_h, fir, fir_steady_state, gauss_markov,
                                  shared_truth, ug)
from navtwin.emulator.rng import stream
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.trajectory import Kinematics, Trajectory
from navtwin.emulator.world import World
from navtwin.protocols import adis16350 as adis

from ..protocols.vectors import SINS_LEVEL
from .world_helpers import made_together, port_bytes, run, sins, variant

NOISE_FREE = """
[imu]
gyro_arw_deg_rt_h = 0.0
gyro_bias_instability_deg_h = 0.0
gyro_bias_deg_h = 0.0
gyro_scale_factor_ppm = 0.0
gyro_misalignment_mrad = 0.0
accel_vrw_m_s_rt_h = 0.0
accel_bias_instability_ug = 0.0
accel_bias_ug = 0.0
accel_scale_factor_ppm = 0.0
accel_misalignment_mrad = 0.0
temperature_noise_c = 0.0
supply_noise_v = 0.0
"""


@pytest.mark.parametrize("n", [1, 2, 4, 16, 64])
def test_bartlett_taps_have_the_datasheet_response(n):
    """Datasheet p. 17: H(f) = [sin(pi N f ts) / (N sin(pi f ts))]^2, unity at DC."""
    h = adis.bartlett_taps(n)
    assert len(h) == 2 * n - 1 and h.sum() == pytest.approx(1.0)
    f = np.linspace(0.001, 0.499, 50)  # in units of fs
    dtft = np.abs(np.exp(-2j * np.pi * np.outer(f, np.arange(len(h)))) @ h)
    expected = (np.sin(np.pi * n * f) / (n * np.sin(np.pi * f))) ** 2
    assert np.allclose(dtft, expected, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 4, 8, 16, 32, 64])
def test_fir_is_scipys_lfilter_to_the_bit(n):
    """The board's FIR in numpy gives lfilter's floats exactly (the golden recordings were made
    with lfilter): the steady start, blocks of every length (1 sample, shorter and longer than
    the filter) and the delays carried between them. scipy is the oracle here only."""
    from scipy.signal import lfilter, lfilter_zi

    taps = adis.bartlett_taps(n)
    x = np.random.default_rng(n).normal(0.0, 3.0, (3000, 3))
    want_zi = lfilter_zi(taps, [1.0]) if n > 1 else np.empty(0)  # it refuses a 1-tap filter
    assert fir_steady_state(taps).tobytes() == want_zi.tobytes()
    want = got = want_zi[:, None] * x[0]
    for block in np.split(x, sorted({1, 3, 2 * n, 2 * n + 1, 1000, 2999})):
        out, want = lfilter(taps, [1.0], block, axis=0, zi=want)
        mine, got = fir(taps, block, got)
        assert mine.tobytes() == out.tobytes() and got.tobytes() == want.tobytes()


def test_bias_process_is_scipys_lfilter_to_the_bit():
    """The Gauss-Markov bias recursion in plain floats gives lfilter's floats exactly, over
    blocks of one and many samples, the state carried between them."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(7)
    phi, drive = math.exp(-1 / 819.2 / 100.0), 1e-5
    want = got = phi * rng.normal(0.0, 1e-3, 3)
    for block in np.split(rng.standard_normal((5000, 3)), [1, 2, 100, 4000]):
        out, zf = lfilter([drive], [1.0, -phi], block, axis=0, zi=want[None, :])
        mine = gauss_markov(phi, got, drive * block)
        want, got = zf[0], phi * mine[-1]
        assert mine.tobytes() == out.tobytes() and got.tobytes() == want.tobytes()


def _imu(sc):
    return Adis16350(sc.imu, sc.site, sc.area, Trajectory(sc.trajectory, sc.tag.z), 0.0,
                     functools.partial(stream, 0))


def test_physics_at_rest_and_on_a_straight_leg():
    """Level at rest, heading 0 = east (x east, y north, z up): f = (0, 0, g) and
    w = W (0, cos L, sin L); at cruise eastward the Coriolis term 2 W x v appears."""
    sc = load_scenario("office")
    imu = _imu(sc)
    lat = math.radians(sc.site.latitude_deg)
    f, w = imu.true_outputs(np.array([1_000_000_000]))
    assert np.allclose(f[0], [0, 0, sc.site.local_gravity], atol=1e-12)
    assert np.allclose(w[0], [0, EARTH_RATE * math.cos(lat), EARTH_RATE * math.sin(lat)], atol=1e-15)
    traj = imu.trajectory
    t_cruise = (traj.speed.t2 + 0.5) * 1e9  # still on the first (eastward) leg
    k = traj.kinematics(np.array([t_cruise]))
    assert k.vel[0, 0] == pytest.approx(sc.trajectory.speed_m_s) and k.yaw[0] == pytest.approx(0)
    f, w = imu.true_outputs(np.array([t_cruise]))
    v = sc.trajectory.speed_m_s
    r = transverse_radius(lat) + sc.tag.z  # still the origin's latitude to 1e-7 rad
    expected = [0, (2 * EARTH_RATE * math.sin(lat) + v * math.tan(lat) / r) * v,
                sc.site.local_gravity - (2 * EARTH_RATE * math.cos(lat) + v / r) * v]
    assert np.allclose(f[0], expected, atol=1e-12)


class Parked:
    """A trajectory standing at *pos* (local m) moving at *vel* (m/s), level, heading *yaw*:
    the kinematics the IMU's physics takes (emulator.trajectory.Kinematics)."""

    def __init__(self, pos, vel=(0.0, 0.0, 0.0), yaw=0.0):
        self.pos, self.vel, self.yaw = np.array(pos, float), np.array(vel, float), yaw

    def kinematics(self, t_ns):
        n = len(t_ns)
        t = (np.asarray(t_ns) / 1e9)[:, None]
        zeros = np.zeros(n)
        return Kinematics(pos=self.pos + t * self.vel, vel=np.tile(self.vel, (n, 1)), acc=np.zeros((n, 3)),
                          roll=zeros, pitch=zeros, yaw=np.full(n, self.yaw), rate=np.zeros((n, 3)))


def _curved(sc, trajectory):
    return Adis16350(sc.imu, sc.site, sc.area, trajectory, 0.0, functools.partial(stream, 0))


def test_parked_1_km_north_the_gyros_sense_the_earth_rate_at_its_own_latitude():
    """The earth rate is projected at the vehicle's current latitude, not the origin's: 1 km
    north (x east, y north) L is 1.57e-4 rad higher, which moves W sin L by 9.5e-9 rad/s."""
    sc = load_scenario("office")
    lat0 = math.radians(sc.site.latitude_deg)
    lat = lat0 + 1000.0 / (meridian_radius(lat0) + sc.site.height_m)
    _, w = _curved(sc, Parked([0.0, 1000.0, 0.0])).true_outputs(np.arange(0, 10**9, 10**7))
    want = EARTH_RATE * np.array([0.0, math.cos(lat), math.sin(lat)])
    assert np.allclose(w.mean(axis=0), want, atol=2e-12, rtol=0)
    assert abs(w.mean(axis=0)[2] - EARTH_RATE * math.sin(lat0)) > 9e-9  # the origin's is off
    # heading north (body x along +y, body y west): the earth rate's north part on body x
    _, w = _curved(sc, Parked([0.0, 1000.0, 0.0], yaw=math.pi / 2)).true_outputs(np.array([0]))
    assert np.allclose(w[0], [EARTH_RATE * math.cos(lat), 0.0, EARTH_RATE * math.sin(lat)], atol=2e-12)


@pytest.mark.parametrize("v", [1.0, 10.0])
def test_driving_north_the_cross_track_gyro_carries_the_transport_rate(v):
    """Heading north at v, the local level turns about east at -v / (R_M + h): body y points
    west, so the y gyro reads +v / (R_M + h) (1.57e-7 rad/s at 1 m/s), and the specific force
    carries the Coriolis (2 w_ie + w_en) x v."""
    sc = load_scenario("office")
    lat0, h = math.radians(sc.site.latitude_deg), sc.site.height_m
    f, w = _curved(sc, Parked([0.0, 0.0, 0.0], [0.0, v, 0.0], yaw=math.pi / 2)).true_outputs(np.array([0]))
    r_m = meridian_radius(lat0) + h
    assert w[0, 1] == pytest.approx(v / r_m, rel=1e-9)
    assert w[0, 0] == pytest.approx(EARTH_RATE * math.cos(lat0), rel=1e-12)
    assert w[0, 2] == pytest.approx(EARTH_RATE * math.sin(lat0), rel=1e-12)
    # ENU: (2 w_ie + w_en) x (0, v, 0) = (-2 W sin L v, 0, -v^2 / R_M); body x north, y west
    assert f[0] == pytest.approx([0.0, 2 * EARTH_RATE * math.sin(lat0) * v,
                                  sc.site.local_gravity - v * v / r_m], rel=1e-12, abs=1e-15)


def test_transport_rate_is_the_turn_rate_of_the_geodetic_position():
    """w_en (ENU) = (-dL/dt, dlam/dt cos L, dlam/dt sin L): checked against the time derivative
    of the geodetic position of a point moving north-east 2 km out, from common.geodesy, in an
    area whose +x points 30 deg east of north."""
    sc = load_scenario("office")
    sc = dataclasses.replace(sc, area=dataclasses.replace(sc.area, x_azimuth_deg=30.0))
    imu = _curved(sc, Parked([0.0, 0.0, 0.0]))
    pos, vel, dt = np.array([1500.0, 1300.0, 2.0]), np.array([3.0, -4.0, 0.0]), 1e-3
    _, w_en = imu.frame_rates(pos[None], vel[None])
    lat, lon, _ = imu.frame.geodetic(np.array([pos - vel * dt, pos + vel * dt]))
    d_lat, d_lon = np.radians(np.diff(lat))[0] / (2 * dt), np.radians(np.diff(lon))[0] / (2 * dt)
    la = math.radians(lat.mean())
    want_enu = np.array([-d_lat, d_lon * math.cos(la), d_lon * math.sin(la)])
    # the plane's axes turn against the local level's by s / R (3e-4 rad here): the tolerance
    assert w_en[0] @ imu.enu_to_n == pytest.approx(want_enu, rel=1e-3)


def test_north_facing_area_projects_earth_rate_on_x(tmp_path):
    sc = variant(tmp_path, "office", "[area]\nx_azimuth_deg = 0.0\n")
    lat = math.radians(sc.site.latitude_deg)
    _, w = _imu(sc).true_outputs(np.array([0]))
    assert np.allclose(w[0], [EARTH_RATE * math.cos(lat), 0, EARTH_RATE * math.sin(lat)], atol=1e-15)


def test_noise_free_level_frame_is_the_wire_format_vector(tmp_path):
    """With every error off, the board's frame seq 1 at rest is wire-formats.md's first test
    vector byte for byte (local g = 9.7952 m/s^2 reads 396 LSB)."""
    sc = variant(tmp_path, "office", "duration_s = 1.0\n" + NOISE_FREE)
    _, events = run(sc)
    frames = [e.data for e in events if e.port == "sins"]
    assert frames[1] == SINS_LEVEL


def test_noise_free_motion_reads_the_truth(tmp_path):
    sc = variant(tmp_path, "office", NOISE_FREE)
    w, events = run(sc)
    s = sins(events)
    lat = math.radians(sc.site.latitude_deg)
    truth = w.truth(0, w.duration_ns)
    t_read = s["t_ns"] - round(sc.board.spi_read_us * 1e3)
    wz = np.interp(t_read, truth["t"], truth["wz"]) + EARTH_RATE * math.sin(lat)
    lsb = math.radians(adis.GYRO_LSB_DPS[300])
    # the filter and the sample hold delay the reading by a few ms: rates change slowly
    assert np.max(np.abs(s["gyro_rad_s"][:, 2] - wz)) < 0.5 * lsb + 0.005
    yaw = np.interp(t_read, truth["t"], np.unwrap(truth["yaw"]))
    ax = np.interp(t_read, truth["t"], truth["ax"])
    ay = np.interp(t_read, truth["t"], truth["ay"])
    forward = ax * np.cos(yaw) + ay * np.sin(yaw)
    left = -ax * np.sin(yaw) + ay * np.cos(yaw)
    alsb = adis.ACCEL_LSB_G * adis.STANDARD_GRAVITY
    assert np.max(np.abs(s["accel_m_s2"][:, 0] - forward)) < 0.5 * alsb + 0.01
    assert np.max(np.abs(s["accel_m_s2"][:, 1] - left)) < 0.5 * alsb + 0.01
    assert np.all(s["accel_m_s2"][:, 2] == 396 * alsb)


@pytest.fixture(scope="module")
def office():
    sc = load_scenario("office")
    w, events = run(sc)
    return sc, w, events, sins(events)


def read_sigma(sc, gyro: bool) -> float:
    """Model noise of one register read: white noise through the Bartlett filter plus
    rounding (reads 10 ms apart see disjoint filter windows, so they are independent)."""
    imu, e = sc.imu, sc.imu.errors
    fs = 1 / imu.sample_period_s
    taps = adis.bartlett_taps(imu.filter_taps)
    if gyro:
        white = math.radians(e.gyro_arw_deg_rt_h) / 60 * math.sqrt(fs)
        lsb = math.radians(adis.GYRO_LSB_DPS[imu.gyro_range_dps])
    else:
        white = e.accel_vrw_m_s_rt_h / 60 * math.sqrt(fs)
        lsb = adis.ACCEL_LSB_G * adis.STANDARD_GRAVITY
    return math.sqrt(white ** 2 * np.sum(taps ** 2) + lsb ** 2 / 12)


def test_stationary_start_reads_local_g_and_no_rotation(office):
    sc, _, _, s = office
    e, g = sc.imu.errors, sc.site.local_gravity
    still = (s["t_ns"] > 0.2e9) & (s["t_ns"] < sc.trajectory.alignment_s * 1e9)
    n = still.sum()
    acc, gyr = s["accel_m_s2"][still], s["gyro_rad_s"][still]
    # the read noise is the modelled one
    assert acc.std(axis=0) == pytest.approx([read_sigma(sc, False)] * 3, rel=0.1)
    assert gyr.std(axis=0) == pytest.approx([read_sigma(sc, True)] * 3, rel=0.1)
    mean_noise = read_sigma(sc, False) / math.sqrt(n)
    bias = math.hypot(ug(e.accel_bias_ug), ug(e.accel_bias_instability_ug))
    tilt = g * e.accel_misalignment_mrad * 1e-3
    sigma_xy = math.sqrt(mean_noise ** 2 + bias ** 2 + tilt ** 2)
    sigma_z = math.sqrt(mean_noise ** 2 + bias ** 2 + (g * e.accel_scale_factor_ppm * 1e-6) ** 2)
    mean = acc.mean(axis=0)
    assert abs(mean[0]) < 4 * sigma_xy and abs(mean[1]) < 4 * sigma_xy
    assert abs(mean[2] - g) < 4 * sigma_z
    gyro_sigma = math.sqrt((read_sigma(sc, True) / math.sqrt(n)) ** 2
                           + deg_h(e.gyro_bias_deg_h) ** 2
                           + deg_h(e.gyro_bias_instability_deg_h) ** 2)
    assert np.all(np.abs(gyr.mean(axis=0)) < 4 * gyro_sigma)  # near zero: 0.4 deg/s at most


def bias_integral_var(floor, tau, times, weights, bin_s=0.5):
    """Variance of sum(w_i b(t_i)) for the in-run bias b (binned): one stationary Gauss-Markov
    term of sigma *floor* (tau > 0) or the flicker bias's terms (tau = 0, emulator.bias)."""
    bins = np.floor(times / bin_s).astype(int)
    w = np.bincount(bins, weights)
    centre = (np.arange(len(w)) + 0.5) * bin_s
    lag = np.abs(centre[:, None] - centre[None, :])
    terms = [(floor ** 2, tau)] if tau > 0 else [(flicker_term_variance(floor), t) for t in FLICKER_TAUS_S]
    cov = sum(q * np.exp(-lag / t) for q, t in terms)
    return float(w @ cov @ w)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_integrated_z_gyro_matches_truth_heading_change(seed):
    """Remove the bias seen in the alignment period, integrate the z gyro over the run and
    compare with the truth heading change; the predicted error is computed from ARW, the
    bias estimate's error, the in-run bias (flicker or Gauss-Markov) and the scale factor."""
    sc = load_scenario("office")
    w, events = run(sc, seed)
    s = sins(events)
    e = sc.imu.errors
    dt = sc.board.period_ms * 1e-3 / (1 + sc.clocks.board_ppm * 1e-6)
    t = s["t_ns"] / 1e9
    align = (t > 0.2) & (t < sc.trajectory.alignment_s)
    move = t >= sc.trajectory.alignment_s
    gz = s["gyro_rad_s"][:, 2]
    n_a, n_m = align.sum(), move.sum()
    heading = dt * np.sum(gz[move] - gz[align].mean())
    truth = w.truth(0, w.duration_ns)
    yaw = np.unwrap(truth["yaw"])
    change = yaw[-1] - yaw[round(sc.trajectory.alignment_s * 1000)]
    assert abs(change) == pytest.approx(2 * math.pi)
    sr = read_sigma(sc, True)
    weights = np.where(move, dt, 0.0) + np.where(align, -n_m * dt / n_a, 0.0)
    var = (np.sum(weights ** 2) * sr ** 2
           + bias_integral_var(deg_h(e.gyro_bias_instability_deg_h), e.gyro_bias_corr_s, t, weights)
           + (e.gyro_scale_factor_ppm * 1e-6 * change) ** 2)
    sigma = math.sqrt(var)
    assert 0.005 < sigma < 0.1  # about 1.8 deg: a meaningful check
    assert abs(heading - change) < 4 * sigma


def test_registers_flags_and_counters(office):
    _, _, _, s = office
    words = s["words"]
    assert np.all(words & adis.ND)  # 819.2 SPS: a new sample before every 10 ms read
    assert not np.any(words & adis.EA)
    assert np.array_equal(s["seq"], np.arange(len(words)) % 65536)
    assert np.all(np.diff(s["t_ns"]) == 10_000_000)
    assert s["temp_c"].mean() == pytest.approx(25.0, abs=0.02)
    assert s["supply_v"].mean() == pytest.approx(5.0, abs=0.002)


def test_slow_sampling_clears_nd_and_repeats_the_registers(tmp_path):
    """SMPL_PRD 20: 0.61035 ms x 21 = 12.8 ms, slower than the reads: some reads find no new
    sample (ND = 0) and then return the same registers as the read before."""
    sc = variant(tmp_path, "office", "duration_s = 10.0\n[imu]\nsmpl_prd = 20\n")
    _, events = run(sc)
    words = sins(events)["words"]
    nd = (words[:, 1] & adis.ND) != 0
    assert np.all(((words & adis.ND) != 0) == nd[:, None])  # every word carries ND
    ts = sc.imu.sample_period_s
    assert 1 - nd.mean() == pytest.approx(1 - 0.01 / ts, abs=0.02)
    stale = np.flatnonzero(~nd)
    stale = stale[stale > 0]
    assert np.array_equal(words[stale] & 0x3FFF, words[stale - 1] & 0x3FFF)


def test_a_last_block_without_a_sample_runs(tmp_path):
    """1.005 s at 12.8 ms a sample: the last block, 1.000 .. 1.005 s, holds no sample (the
    next is at 1.011 s); the run ends with every frame, the last one reading the sample of
    0.998 s, which arrived after the read before it (ND)."""
    sc = variant(tmp_path, "office", "duration_s = 1.005\n[imu]\nsmpl_prd = 20\n")
    _, events = run(sc)
    s = sins(events)
    assert len(s["t_ns"]) == 101 and s["t_ns"][-1] > 1_000_000_000
    assert s["words"][-1, 1] & adis.ND


def test_supply_out_of_range_sets_ea(tmp_path):
    sc = variant(tmp_path, "office", "duration_s = 2.0\n[imu]\nsupply_v = 5.3\n")
    s = sins(run(sc)[1])
    assert np.all(s["words"] & adis.EA)
    assert s["supply_v"].mean() == pytest.approx(5.3, abs=0.002)


def test_fast_turns_saturate_the_75_dps_range(tmp_path):
    """2 m/s round 0.5 m turns is about 230 deg/s: the z gyro clips at 75 deg/s, 4095 LSB of
    0.018315 deg/s, and EA flags the overrange while the turn lasts."""
    sc = variant(tmp_path, "office", "[imu]\ngyro_range_dps = 75\nfilter_taps = 16\n"
                                     "[trajectory]\nspeed_m_s = 2.0\naccel_m_s2 = 1.0\nturn_radius_m = 0.5\n"
                                     "transition_m = 0.2\nalignment_s = 1.0\n")
    w, events = run(sc)
    s = sins(events, gyro_range=75)
    raw_z = adis.signed(s["words"][:, 3], 14)
    ea = (s["words"][:, 0] & adis.EA) != 0
    assert np.abs(raw_z).max() == 4095
    truth = w.truth(0, w.duration_ns)
    fast = np.abs(np.interp(s["t_ns"], truth["t"], truth["wz"])) > math.radians(90)
    slow = np.abs(np.interp(s["t_ns"], truth["t"], truth["wz"])) < math.radians(40)
    assert fast.sum() > 50 and ea[fast].mean() > 0.95 and not ea[slow].any()
    assert np.mean(np.abs(raw_z[fast]) == 4095) > 0.9  # but for the filter's lag at the onset


def test_same_seed_same_bytes_other_seed_other_bytes():
    sc = load_scenario("office")
    a = port_bytes(run(sc, 5)[1], "sins")
    b = port_bytes(run(sc, 5)[1], "sins")
    c = port_bytes(run(sc, 6)[1], "sins")
    assert a == b and a != c and len(a) == len(c)


def test_seeds_made_within_shared_truth_compute_the_motion_once_and_make_the_same_events():
    """A sweep's task makes its seeds within shared_truth: the second seed of a scenario
    takes every block's error-free outputs from the first, and every event (the SINS frames'
    bytes, the packets, the reports) is what the seed makes alone."""
    sc = load_scenario("office")

    def events(seed):
        return World(sc, seed, air=False).advance(4_000_000_000)

    alone = [events(seed) for seed in (1, 2)]
    with shared_truth():
        shared = [events(1)]
        blocks = len(imu._shared())
        shared.append(events(2))
        assert len(imu._shared()) == blocks == 4  # a second's block each, none added by seed 2
        other = []  # another thread is outside it: it keeps nothing
        thread = threading.Thread(target=lambda: other.append(imu._shared()))
        thread.start()
        thread.join()
        assert other == [None]
    assert imu._shared() is None
    assert shared == alone and alone[0] != alone[1]


@pytest.mark.parametrize("toml", ["", '[imu]\ngrade = "paper003"\n',
                                  "[imu]\ngyro_bias_corr_s = 300.0\naccel_rrw_ug_rt_h = 20.0\n"])
def test_worlds_made_together_equal_each_made_alone(tmp_path, toml):
    """World.make_together runs the seeds' IMU blocks along one seed axis (the flicker bias,
    a Gauss-Markov bias and a rate random walk here); every seed's samples and events are
    those it makes alone, to the bit, and a world that is not alike (another grade) is made
    in its own group of the same call."""
    sc = variant(tmp_path, "office", toml, "together") if toml else load_scenario("office")
    other = variant(tmp_path, "office", '[imu]\ngrade = "paper003"\ngyro_arw_deg_rt_h = 0.01\n',
                    "other")
    until = 2_500_000_000
    alone = [World(w_sc, s) for w_sc, s in ((sc, 1), (sc, 2), (sc, 5), (other, 1))]
    alone_events = [w.advance(until) for w in alone]
    together = [World(w_sc, s) for w_sc, s in ((sc, 1), (sc, 2), (sc, 5), (other, 1))]
    World.make_together(together, until)
    assert [w.advance(until) for w in together] == alone_events
    for a, b in zip(alone, together):
        ia, ib = a.vehicles[0].imu, b.vehicles[0].imu
        assert np.array_equal(ia._gyro, ib._gyro) and np.array_equal(ia._accel, ib._accel)
        assert np.array_equal(ia._temp, ib._temp) and ia.made_ns == ib.made_ns >= until
    assert not np.array_equal(alone[0].vehicles[0].imu._gyro, alone[1].vehicles[0].imu._gyro)


#: (scenario, overrides): boards alike and not (each seed's own alarms, the magnetometer's
#: frames between, a board reset's marks and seq, 32-bit words, three cars of other paths)
BOARDS = {
    "office": ("office", None),
    "alarms": ("office", "[imu]\nsupply_noise_v = 0.2\n"),  # EA: the supply out of range
    "reset": ("office", '[[faults]]\nkind = "board_reset"\nstart_s = 0.4\nend_s = 1.3\n'),
    "wide-magnetometer": ("rssi-centroid", None),
    "convoy": ("office-convoy", None),
}


@pytest.mark.parametrize("case", BOARDS)
def test_boards_made_together_equal_each_made_alone(tmp_path, case):
    """World.make_together reads the seeds' ADIS16350 registers and builds their SINS frames
    along one seed axis (Board.frames_together); every seed's events (t_ns, bytes, ledger
    marks) are those it makes alone, to the bit, beside a world of another scenario."""
    made = made_together(tmp_path, *BOARDS[case], "corridor", "sins")
    if case == "reset":
        assert any(e.marks for e in made[0] if e.port == "sins")
