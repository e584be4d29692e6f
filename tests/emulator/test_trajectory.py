"""The true motion: exact closure, smoothness, consistency of position, velocity,
acceleration and rates (checked by numerical differentiation and integration, i.e. by
methods independent of the closed forms in emulator.trajectory)."""
import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from navtwin.emulator.scenario import SCENARIO_NAMES, load_scenario
from navtwin.emulator.trajectory import Path, Trajectory, wrap
from navtwin.emulator.world import World

MS = 1_000_000


@pytest.fixture(scope="module", params=SCENARIO_NAMES)
def lab(request):
    sc = load_scenario(request.param)
    w = World(sc)
    return sc, w.truth(0, w.duration_ns)


def test_truth_grid_is_1khz(lab):
    sc, tr = lab
    assert tr["t"][0] == 0 and np.all(np.diff(tr["t"]) == MS)
    assert len(tr) == round(sc.duration_s * 1000)


def test_alignment_at_rest_at_start(lab):
    sc, tr = lab
    still = tr["t"] < sc.trajectory.alignment_s * 1e9
    x0, y0 = sc.trajectory.waypoints[0]
    (x1, y1) = sc.trajectory.waypoints[1]
    assert np.all(tr["x"][still] == x0) and np.all(tr["y"][still] == y0)
    for f in ("vx", "vy", "vz", "ax", "ay", "az", "wx", "wy", "wz", "roll", "pitch"):
        assert np.all(tr[f][still] == 0.0), f
    assert np.allclose(tr["yaw"][still], math.atan2(y1 - y0, x1 - x0))
    assert np.all(tr["z"] == sc.tag.z)


def test_derivatives_match_by_finite_differences(lab):
    _, tr = lab
    dt = 1e-3
    for p, v, a in (("x", "vx", "ax"), ("y", "vy", "ay")):
        dpos = np.gradient(tr[p], dt)
        assert np.max(np.abs(dpos - tr[v])[1:-1]) < 1e-5
        dvel = np.gradient(tr[v], dt)
        assert np.max(np.abs(dvel - tr[a])[1:-1]) < 2e-3  # jerk is bounded, not continuous
    dyaw = np.gradient(np.unwrap(tr["yaw"]), dt)
    assert np.max(np.abs(dyaw - tr["wz"])[1:-1]) < 2e-3


def largest_steps(traj, end_ns: int, step_ns: int, block: int = 400_000) -> dict[str, float]:
    """The largest change between samples *step_ns* apart over [0, end_ns) of velocity,
    acceleration and rate, in blocks that share their edge sample: rssi-centroid's 1500 s at
    125 us in one piece took 3.5 GB."""
    out = dict.fromkeys(("vel", "acc", "rate"), 0.0)
    for lo in range(0, end_ns, block * step_ns):
        k = traj.kinematics(np.arange(lo, min(lo + (block + 1) * step_ns, end_ns), step_ns))
        for name in out:
            out[name] = max(out[name], float(np.max(np.abs(np.diff(getattr(k, name), axis=0)), initial=0.0)))
    return out


def test_acceleration_and_rate_are_continuous(lab):
    """No steps: the largest change between samples shrinks in proportion to the sampling
    interval (a jump would not shrink)."""
    sc, tr = lab
    traj = Trajectory(sc.trajectory, sc.tag.z)
    end = round(sc.duration_s * 1e9)
    coarse, fine = largest_steps(traj, end, MS), largest_steps(traj, end, MS // 8)
    for name in ("vel", "acc", "rate"):
        # a straight line (the calibration walk) never turns: its rate is 0 throughout
        assert fine[name] < coarse[name] / 6 or coarse[name] == fine[name] == 0, name
    speed = np.hypot(tr["vx"], tr["vy"])
    heading = np.arctan2(tr["vy"], tr["vx"])
    moving = speed > 1e-6
    assert np.allclose(wrap(heading[moving] - tr["yaw"][moving]), 0, atol=1e-9)


def test_ends_at_rest_after_the_laps(lab):
    sc, tr = lab
    traj = Trajectory(sc.trajectory, sc.tag.z)
    end = tr["t"] >= traj.speed.t4 * 1e9
    if end.any():
        assert np.all(np.hypot(tr["vx"][end], tr["vy"][end]) == 0)
    # the distance driven is the laps' length (numerical integration of the speed)
    driven = cumulative_trapezoid(np.hypot(tr["vx"], tr["vy"]), dx=1e-3)[-1]
    expected = traj.path.length * sc.trajectory.loops if end.any() else traj.speed.evaluate(tr["t"][-1:] / 1e9)[0][0]
    assert driven == pytest.approx(expected, abs=1e-3)


def test_turns_keep_radius_and_speed_limits(lab):
    sc, tr = lab
    curvature = np.abs(tr["wz"]) / np.maximum(np.hypot(tr["vx"], tr["vy"]), 1e-9)
    moving = np.hypot(tr["vx"], tr["vy"]) > 0.05
    assert np.max(curvature[moving]) <= 1 / sc.trajectory.turn_radius_m + 1e-9
    assert np.max(np.hypot(tr["vx"], tr["vy"])) <= sc.trajectory.speed_m_s + 1e-12
    tangential = np.abs(tr["ax"] * tr["vx"] + tr["ay"] * tr["vy"]) / np.maximum(np.hypot(tr["vx"], tr["vy"]), 1e-9)
    assert np.max(tangential) <= sc.trajectory.accel_m_s2 * (1 + 1e-9)


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_path_matches_numerical_integration_of_its_curvature(name):
    """Integrate heading -> position numerically from the curvature profile alone and compare
    with the closed forms (Fresnel integrals for the clothoids)."""
    sc = load_scenario(name)
    t = sc.trajectory
    path = Path(t.waypoints, t.closed, t.turn_radius_m, t.transition_m)
    s = np.linspace(0, path.length, 400_001)
    pos, psi, kappa = path.evaluate(s[:-1])
    pos = np.append(pos, path.evaluate(s[-1:] - 1e-12)[0])
    psi_num = psi[0] + cumulative_trapezoid(np.append(kappa, kappa[-1]), s, initial=0)
    assert np.max(np.abs(psi_num[:-1] - psi)) < 1e-7
    xy = cumulative_trapezoid(np.exp(1j * psi_num), s, initial=0) + pos[0]
    assert np.max(np.abs(xy - pos)) < 1e-6
    if t.closed:
        assert abs(path.end - complex(*t.waypoints[0])) < 1e-9
        assert path.end_heading - psi[0] == pytest.approx(2 * math.pi * round((path.end_heading - psi[0]) / (2 * math.pi)))


def test_path_runs_along_the_legs_between_turns():
    """Away from the corners the line lies on the polyline's legs."""
    sc = load_scenario("office")
    t = sc.trajectory
    path = Path(t.waypoints, t.closed, t.turn_radius_m, t.transition_m)
    pos, _, kappa = path.evaluate(np.linspace(0, path.length, 20001))
    pts = [complex(*p) for p in t.waypoints] + [complex(*t.waypoints[0])]
    straight = pos[kappa == 0]
    dist = np.min([np.abs(((straight - a) * np.conj(b - a)).imag / abs(b - a)) for a, b in zip(pts, pts[1:])], axis=0)
    assert np.max(dist) < 1e-9


def test_open_line_and_short_transitions(tmp_path):
    from .world_helpers import variant
    sc = variant(tmp_path, "office", "[trajectory]\nclosed = false\nwaypoints = [[1.0, 1.0], [8.0, 1.0], [8.0, 6.0]]\n"
                                      "turn_radius_m = 1.0\ntransition_m = 3.0\n")
    traj = Trajectory(sc.trajectory, sc.tag.z)
    pos, psi, kappa = traj.path.evaluate(np.array([0.0, traj.path.length]))
    assert pos[0] == pytest.approx(1 + 1j) and pos[1] == pytest.approx(8 + 6j, abs=1e-9)
    assert psi[1] == pytest.approx(math.pi / 2)
    assert np.max(kappa) < 1.0  # two long clothoids meet below 1/R instead of an arc
