"""The host on outage-bridging's field of 1402 anchors (host/configs/outage-bridging.toml):
one WSN fix per in-range cycle, from that cycle's exchanges alone, at their mean time, only
where the training areas' anchors reach, and about 004's 0.2 m accurate; the layout never
builds the field's 2 M anchor pairs."""
import numpy as np
import pytest

from navtwin.host import config as host_config
from navtwin.host import ranging
from navtwin.host.measurements import Fix
from navtwin.host.wsn import AnchorLayout
from navtwin.lab.run import run_in_memory, truth

BOXES = [(500.0, 0.0, 650.0, 150.0), (320.0, 160.0, 420.0, 260.0)]  # the two grids' boxes
RANGE_M = 11.0


def _near_a_grid(x: float, y: float, margin: float) -> bool:
    return any(x0 - margin <= x <= x1 + margin and y0 - margin <= y <= y1 + margin
               for x0, y0, x1, y1 in BOXES)


@pytest.fixture(scope="module")
def run():
    """130 s: area 1 (the start), outage 1 and the way into area 2."""
    cycles = []
    fix = ranging.Ranging.fix
    mp = pytest.MonkeyPatch()
    mp.setattr(ranging.Ranging, "fix", lambda self, c: cycles.append((c, fix(self, c))) or cycles[-1][1])
    try:
        estimates, pipe = run_in_memory("outage-bridging", 4, duration=130.0)
    finally:
        mp.undo()
    return cycles, estimates, truth("outage-bridging", 4)


def test_fixes_only_where_the_grids_reach_and_about_20_cm(run):
    cycles, _, tr = run
    fixes = [(c, f) for c, f in cycles if isinstance(f, Fix)]
    assert len(fixes) > 95
    errors = []
    for c, f in fixes:
        k = int(round(f.t * 1000))
        x, y = tr["x"][k], tr["y"][k]
        assert _near_a_grid(x, y, RANGE_M)
        if _near_a_grid(x, y, 0.0):
            errors.append(float(np.hypot(f.p[0] - x, f.p[1] - y)))
    assert 0.1 < np.mean(errors) < 0.3 and max(errors) < 1.0
    # the middle of outage 1 (the truth 20 m or more from both grids) has no fix
    t_out = [t for t, x, y in zip(tr["t"][::1000], tr["x"][::1000], tr["y"][::1000])
             if not _near_a_grid(x, y, 20.0)]
    assert len(t_out) > 10 and not [f for _, f in fixes if t_out[0] <= f.t <= t_out[-1]]


def test_each_fix_is_one_cycles_exchanges_at_their_mean_time(run):
    cycles, _, _ = run
    inside = [c for c, f in cycles if isinstance(f, Fix) and len(c.valid_anchors) >= 10]
    assert len(inside) > 80
    for c in inside:
        assert len(set(c.anchors)) == len(c.anchors)  # no anchor twice: one cycle
        assert c.times[-1] - c.times[0] < 0.6  # 16 slots of 25 ms at most, not the next cycle's
    counts = [len(c.anchors) for c, _ in cycles[15:95]]  # well inside area 1
    assert 10 <= min(counts) and max(counts) <= 25
    for c, f in cycles:
        if isinstance(f, Fix):
            assert f.t == pytest.approx(np.mean(c.valid_times), abs=1e-9)


def test_the_wsn_track_reports_where_the_fixes_are(run):
    _, estimates, tr = run
    wsn = [e for e in estimates if e.filter == "wsn" and not e.extrapolated]
    assert wsn and all(_near_a_grid(tr["x"][int(round(e.t * 1000))], tr["y"][int(round(e.t * 1000))], RANGE_M + 2.0)
                       for e in wsn)


def test_the_layout_of_1402_anchors_computes_the_pairs_it_is_asked():
    cfg = host_config.load("outage-bridging")
    layout = AnchorLayout(cfg.anchors)
    assert len(layout.ids) == 1402 and not layout._baselines
    assert layout.baseline(1, 2) == pytest.approx(5.0) and layout.baseline(1, 1001) == pytest.approx(np.hypot(180, 160))
    assert len(layout._baselines) == 2
