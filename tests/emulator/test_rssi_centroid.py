"""The rssi-centroid scenario (003 sect. 4.1): its nodes are 003's degrees placed by the
site's local frame, it runs at --speed max, and its RSSI falls with the configured path-loss
exponent against the true distance."""
import math

import numpy as np
import pytest

from navtwin.common.geodesy import LocalFrame
from navtwin.emulator.scenario import load_scenario
from navtwin.protocols.stream import Frame, nanoloc_decoder

from ..helpers import navtwin

NODES_DEG = {1: (32.0, 118.01), 2: (32.01, 118.02), 3: (32.02, 118.01), 4: (32.01, 118.0)}


def test_the_nodes_are_003s_degrees_in_the_local_frame():
    sc = load_scenario("rssi-centroid")
    frame = LocalFrame(32.0, 118.0, 0.0, 90.0)  # 003's start, x east, y north
    assert sc.frame == frame
    for a in sc.anchors:
        x, y, _ = frame.local(*NODES_DEG[a.id])
        assert sc.anchor_position(a) == pytest.approx((x, y, sc.tag.z), abs=1e-9)
    assert sc.trajectory.waypoints[0] == (0.0, 0.0)  # the start is 32 N 118 E
    assert sc.imu.grade == "paper003" and sc.magnetometer.enabled
    # 1500 s north at 1 m/s ends inside the nodes' box, every node within radio range
    end = np.array([0.0, sc.trajectory.speed_m_s * sc.duration_s])
    farthest = max(math.dist(p, sc.anchor_position(a)[:2]) for a in sc.anchors for p in ((0, 0), end))
    assert farthest < sc.ranging.radio_range_m
    lat, lon, _ = frame.geodetic([*end, 0.0])
    assert 32.0 < lat < 32.02 and lon == pytest.approx(118.0)


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("rc")
    done = navtwin("emulate", "--scenario", "rssi-centroid", "--speed", "max", "--duration", 30,
                   "--quiet", "--link-dir", out / "links", "--record", out / "rec")
    assert done.returncode == 0, done.stderr
    return out / "rec"


def test_a_short_stretch_runs_and_rssi_has_the_configured_slope(short_run):
    """Regress RSSI on -10 lg d over every report of 30 s (all four nodes, 0.9 to 2.4 km):
    the 99 % confidence interval of n holds the configured exponent and is narrow enough to
    tell 2 from 2.2 (seed 3 gives n = 2.07 +- 0.08); the intercept is RSSI(1 m) and the
    residual the shadowing with the whole-dBm rounding."""
    sc = load_scenario("rssi-centroid")
    frames = nanoloc_decoder().decode((short_run / "nanoloc.bin").read_bytes())
    assert frames and all(isinstance(f, Frame) for f in frames)
    every = sc.ranging.anchor_exchange_every_cycles
    among = [x.fields for x in frames if x.fields["tag"] != sc.tag.id]  # the nodes' of each other
    assert len(among) == pytest.approx(len(frames) / every, abs=8)
    f = [x.fields for x in frames if x.fields["tag"] == sc.tag.id]
    anchor = np.array([x["anchor"] for x in f])
    rssi = np.array([x["rssi"] for x in f], dtype=float)
    t_ns = np.array([x["t_us"] for x in f], dtype=np.int64) * 1000  # the network clock is ideal
    assert set(anchor.tolist()) == {1, 2, 3, 4}
    assert len(f) == pytest.approx(30 * 4 * 1000 / sc.ranging.cycle_ms * (1 - 1 / every), abs=8)
    truth = np.genfromtxt(short_run / "truth.csv", delimiter=",", names=True)
    assert truth["x"][-1] == pytest.approx(0.0, abs=1e-6)
    assert truth["y"][-1] == pytest.approx(30.0 - 0.75, abs=0.01)  # 1 m/s after a 1.5 s ramp
    pos = np.column_stack([np.interp(t_ns, truth["t"], truth[c]) for c in "xyz"])
    where = np.array([sc.anchor_position(a) for a in sc.anchors])[anchor - 1]
    d = np.linalg.norm(pos - where, axis=1)
    assert 900 < d.min() and d.max() < 2450
    design = np.column_stack((np.ones_like(d), -10 * np.log10(d)))
    coef, res, *_ = np.linalg.lstsq(design, rssi, rcond=None)
    s2 = res[0] / (len(d) - 2)
    se = np.sqrt(np.diag(s2 * np.linalg.inv(design.T @ design)))
    n, half = coef[1], 2.576 * se[1]
    assert n - half <= sc.ranging.path_loss_exponent <= n + half
    assert half < 0.1
    assert coef[0] == pytest.approx(sc.ranging.rssi_1m_dbm, abs=2.576 * se[0])
    assert math.sqrt(s2) == pytest.approx(math.hypot(sc.ranging.shadowing_db, 1 / math.sqrt(12)), rel=0.1)
