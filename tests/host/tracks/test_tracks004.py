"""Paper 004's tracks (docs/filters.md, "Paper 004's tracks"): the closed-loop H-infinity
update is 004's recursion (2.9), and on data with a biased INS the relative-error filters
bound it while fixes come and the bridging models beat the coasting INS in an outage (on the
emulated field: tests/lab/test_outage_bridging.py)."""
from __future__ import annotations

import numpy as np
import pytest

from navtwin.host.estimator import Estimator
from navtwin.host.measurements import Exchange, ImuSample
from navtwin.host.settings import EstimatorConfig
from navtwin.host.tracks.relative import transition

from ...helpers import GRAVITY, LATITUDE_DEG, OFFICE_ANCHORS
from ..navsynth import drive_after_rest, exchanges

hinf = pytest.importorskip("navtwin.host.filters.hinf")
pytest.importorskip("cvxpy", reason="the lmi extra (pip install 'navtwin[lmi]')")

TRACKS = ("sins", "kf-rel", "hinf", "hinf+lssvm", "hinf+bp")
ALIGN_S, DURATION_S, OUTAGE = 5.0, 150.0, (80.0, 120.0)


def test_the_closed_loop_update_is_004s_recursion():
    """Fed back after every update, K Y_k = A^-1 B_f Y_k (host.tracks.hinf) accumulates to the
    filtered estimate of 004's predictor (2.9) run open loop on the same errors: X_k|k =
    A^-1 X^_k+1."""
    gain = hinf.solve_gain(1.0, 1e-3, np.full(4, 0.05), np.array([0.2, 0.2, 0.3, 0.3]))
    A = transition(1.0)
    K = np.linalg.solve(A, gain.Bf)
    rng = np.random.default_rng(4)
    x = rng.normal(0.0, 1.0, 4)  # the INS's errors, open loop
    predicted = np.zeros(4)  # 004's X^_k (2.9)
    fed_back = np.zeros(4)  # the corrections so far, carried to time k
    for _ in range(50):
        y = x + rng.normal(0.0, 0.2, 4)
        predicted = gain.Af @ predicted + gain.Bf @ y
        fed_back = fed_back + K @ (y - fed_back)  # the closed loop measures what is left
        np.testing.assert_allclose(fed_back, np.linalg.solve(A, predicted), rtol=0, atol=1e-9)
        x = A @ x + rng.normal(0.0, 0.05, 4)
        fed_back = A @ fed_back


def run(seed: int):
    """Mean horizontal error of each track while fixes come (20 s to the outage) and in the
    outage, on an office ellipse with a biased, noisy IMU and 1 s cycles of four ranges."""
    rng = np.random.default_rng(seed)
    traj, t, tr, gyro, accel = drive_after_rest(rng, align_s=ALIGN_S, duration_s=DURATION_S,
                                                arw_deg_rt_hr=0.5, vrw_m_s_rt_hr=0.2,
                                                accel_bias=(0.01, -0.008, 0.0), gyro_bias=(0.0, 0.0, 1e-4))
    ex = [e for e in exchanges(traj, OFFICE_ANCHORS, duration=DURATION_S, sigma=0.15, rng=rng, cycle=1.0,
                               t0=0.003) if not OUTAGE[0] <= e[0] < OUTAGE[1]]
    cfg = EstimatorConfig(anchors=OFFICE_ANCHORS, latitude_deg=LATITUDE_DEG, local_gravity=GRAVITY,
                          start=tuple(tr.p[0]), heading_deg=0.0, alignment_s=ALIGN_S, cycle_s=1.0,
                          range_sigma_m=0.15, wsn_method="toa", p0_sigma=(0.1, 1e-3, 0.1), filters=TRACKS)
    est = Estimator(cfg)
    records = [(ti, 0, ImuSample(ti, g, f)) for ti, g, f in zip(t, gyro, accel)]
    records += [(te, 1, Exchange(te, a, d)) for te, a, d in ex]
    errors: dict[str, list] = {n: [] for n in TRACKS}
    for _, _, rec in sorted(records, key=lambda r: r[:2]):
        for e in est.feed(rec):
            k = int(round(e.t * 100))
            if k < len(t):
                errors[e.filter].append((e.t, np.hypot(e.x - tr.p[k, 0], e.y - tr.p[k, 1])))
    out = {}
    for name, rows in errors.items():
        a = np.array(rows)
        covered = (a[:, 0] > 20.0) & (a[:, 0] < OUTAGE[0])
        outage = (a[:, 0] >= OUTAGE[0]) & (a[:, 0] < OUTAGE[1])
        out[name] = (a[covered, 1].mean(), a[outage, 1].mean())
    return out, {tk.name: tk for tk in est.tracks}


@pytest.mark.parametrize("seed", [1, 2])
def test_the_filters_bound_the_ins_and_the_bridges_beat_coasting(seed):
    err, tracks = run(seed)
    sins_covered = err["sins"][0]
    for name in ("kf-rel", "hinf"):
        assert err[name][0] < 0.05 * sins_covered, (name, err)
        assert err[name][0] < 0.5, (name, err)  # about the fixes' own error
    for name in ("hinf+lssvm", "hinf+bp"):
        assert err[name][0] == err["hinf"][0]  # the same filter while fixes come
    assert err["hinf+lssvm"][1] < err["hinf"][1], err  # bridged beats coasting
    assert err["hinf+lssvm"][1] < 0.2 * err["sins"][1], err
    lssvm = tracks["hinf+lssvm"]
    # one fit when the outage starts, one correction a period through it (the fix that ends
    # it reaches the track up to a period after its time)
    assert lssvm.updates["fit"] == 1
    assert 39 <= lssvm.updates["bridge"] <= 42
    assert lssvm.updates["fix"] == tracks["hinf"].updates["fix"] == tracks["kf-rel"].updates["fix"]


def test_registered_after_003s():
    from navtwin.host.tracks import BUILT_IN, get
    from navtwin.host.tracks.bridging import HinfBpTrack, HinfLssvmTrack
    from navtwin.host.tracks.hinf import HinfTrack

    assert BUILT_IN[11:] == ("kf-rel", "hinf", "hinf+lssvm", "hinf+bp")
    assert get("hinf") is HinfTrack and issubclass(HinfLssvmTrack, HinfTrack) and issubclass(HinfBpTrack, HinfTrack)
