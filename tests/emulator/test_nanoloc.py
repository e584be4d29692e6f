"""nanoLOC exchanges, checked on the decoded gateway reports: the wire-format vector's
physics, distances against truth within the modelled noise, the crystal-offset behaviour of
four-timestamp versus single-sided ranging, outages, NLOS, RSSI and the papers' numbers."""
import math

import numpy as np
import pytest

from navtwin.emulator.scenario import load_scenario
from navtwin.protocols.nanoloc import SPEED_OF_LIGHT, STATUS_COMPLETE, STATUS_TIMEOUT

from ..helpers import OFFICE_ANCHORS
from ..protocols.vectors import NANOLOC_5M
from .world_helpers import made_together, reports, run, true_distances, variant

QUIET = """
[ranging]
sigma0_m = 0.0
sigma_per_m = 0.0
reply_jitter_ns = 0.0
"""


def anchors_toml(anchors, **extra):
    out = ""
    for i, (x, y) in enumerate(anchors):
        out += f"[[anchors]]\nid = {i + 1}\nx = {x}\ny = {y}\n"
        out += "".join(f"{k} = {v[i] if isinstance(v, tuple) else v}\n" for k, v in extra.items())
    return out


def test_noise_free_exchange_gives_the_wire_format_vector_taus(tmp_path):
    """wire-formats.md section 3: 5.000 m, 100 us replies, ideal clocks -> the vector's taus."""
    # anchor 1 moved to 5.000 m from the tag's start (6.0, 1.8), the others where they are
    others = [(x, y) for a, (x, y, _) in OFFICE_ANCHORS.items() if a != 1]
    sc = variant(tmp_path, "office", "duration_s = 1.0\n" + QUIET + anchors_toml([(1.0, 1.8), *others]))
    _, events = run(sc)
    r = reports(events)
    first = np.flatnonzero(r["anchor"] == 1)[0]
    vector = reports([type(events[0])(0, "nanoloc", NANOLOC_5M)])
    assert r["tau"][first].tolist() == vector["tau"][0].tolist()
    assert r["status"][first] == STATUS_COMPLETE and r["tag"][first] == 0x10
    assert r["d"][first] == pytest.approx(4.99994, abs=1e-5)


@pytest.fixture(scope="module")
def office():
    sc = load_scenario("office")
    w, events = run(sc)
    return sc, w, events, reports(events)


def test_one_report_per_exchange_in_slot_order(office):
    sc, _, _, r = office
    cycles = round(sc.duration_s * 10)
    assert len(r["seq"]) == 4 * cycles
    assert np.array_equal(r["seq"], np.arange(len(r["seq"])) % 65536)
    assert np.array_equal(r["anchor"], np.tile([a.id for a in sc.anchors], cycles))
    expected_us = 5000 + np.repeat(np.arange(cycles), 4) * 100_000 + np.tile(np.arange(4), cycles) * 25_000
    assert np.array_equal(r["t_us"], expected_us)
    assert np.all(r["status"] == STATUS_COMPLETE)
    assert np.all(np.diff(r["t_ns"]) >= round(32 * 10 / 115200 * 1e9))  # the gateway's line


def test_distances_match_truth_within_the_modelled_noise(office):
    """001 eq. 13: d~ - (f d + c_i) ~ N(0, sigma(d)^2), sigma(d) = sigma0 + k d."""
    sc, w, _, r = office
    truth = true_distances(w, sc, r)
    rg = sc.ranging
    bias = {a.id: a.range_bias_m for a in sc.anchors}
    expected = rg.scale * truth + np.array([bias[a] for a in r["anchor"]])
    z = (r["d"] - expected) / (rg.sigma0_m + rg.sigma_per_m * truth)
    n = len(z)
    assert abs(z.mean()) < 4 / math.sqrt(n)
    assert z.std() == pytest.approx(1.0, abs=4 / math.sqrt(2 * n))
    for a in bias:  # and per anchor
        za = z[r["anchor"] == a]
        assert abs(za.mean()) < 4 / math.sqrt(len(za))


def stationary(tmp_path, name, anchor_ppm, tag_ppm, sigma=0.05):
    return variant(tmp_path, "office", f"""duration_s = 60.0
[trajectory]
alignment_s = 100.0
[tag]
ppm = {tag_ppm}
[ranging]
sigma0_m = {sigma}
sigma_per_m = 0.0
""" + anchors_toml([(x, y) for x, y, _ in OFFICE_ANCHORS.values()], ppm=anchor_ppm), name)


@pytest.mark.parametrize("anchor_ppm, tag_ppm", [(20.0, -20.0), (0.0, 0.0), (-15.0, 25.0)])
def test_four_timestamp_cancels_clock_offsets_single_sided_does_not(tmp_path, anchor_ppm, tag_ppm):
    """With crystal offsets e_A, e_T the anchor measures tau1 = (2 tof + P_T)(1 + e_A) around the
    tag's reply P_T = tag_reply / (1 + e_T), which the tag measures as tau2 = tag_reply: so
    c (tau1 - tau2) / 2 = (1 + e_A) d + c tag_reply (e_A - e_T) / (2 (1 + e_T)), while the
    four-timestamp sum leaves d (1 + (e_A + e_T)/2) (wire-formats.md section 3)."""
    sc = stationary(tmp_path, "clocks", anchor_ppm, tag_ppm)
    w, events = run(sc)
    r = reports(events)
    d = true_distances(w, sc, r)
    e_a, e_t = anchor_ppm * 1e-6, tag_ppm * 1e-6
    rg = sc.ranging
    n = len(d)
    four = r["d"] - d * (1 + (e_a + e_t) / 2) - np.array([a.range_bias_m for a in sc.anchors])[r["anchor"] - 1]
    assert abs(four.mean()) < 4 * rg.sigma0_m / math.sqrt(n)
    predicted = SPEED_OF_LIGHT * rg.tag_reply_us * 1e-6 * (e_a - e_t) / (2 * (1 + e_t))
    single = r["d_single"] - d * (1 + e_a) - np.array([a.range_bias_m for a in sc.anchors])[r["anchor"] - 1]
    assert single.mean() - predicted == pytest.approx(0, abs=4 * math.sqrt(2) * rg.sigma0_m / math.sqrt(n))
    if anchor_ppm == 20.0:
        assert predicted == pytest.approx(0.5996, abs=1e-4)  # 40 ppm over a 100 us reply


def test_anchor_outage_reports_timeouts(tmp_path):
    sc = load_scenario("corridor-outage")
    w, events = run(sc)
    r = reports(events)
    t_s = r["t_us"] / 1e6
    silent = (r["anchor"] == 2) & (((t_s >= 18) & (t_s < 23)) | ((t_s >= 40) & (t_s < 45)))
    assert silent.sum() == 100  # 10 s of 10 Hz cycles
    assert np.all(r["status"][silent] == STATUS_TIMEOUT)
    assert np.all(r["tau"][silent] == 0) and np.all(r["rssi"][silent] == -128)
    assert np.all(r["status"][~silent] == STATUS_COMPLETE)
    assert len(r["seq"]) == 4 * 600  # one report per exchange, timeouts included


def test_nlos_episode_adds_a_positive_bias(tmp_path):
    sc = variant(tmp_path, "office", """[[faults]]
kind = "nlos"
anchor = 3
start_s = 20.0
end_s = 50.0
bias_m = 1.0
attenuation_db = 8.0
""")
    w, events = run(sc)
    r = reports(events)
    truth = true_distances(w, sc, r)
    rg = sc.ranging
    bias = {a.id: a.range_bias_m for a in sc.anchors}
    err = r["d"] - truth - np.array([bias[a] for a in r["anchor"]])
    t_s = r["t_us"] / 1e6
    inside = (r["anchor"] == 3) & (t_s >= 20) & (t_s < 50)
    outside = (r["anchor"] == 3) & ~inside
    sigma = rg.sigma0_m + rg.sigma_per_m * truth
    n = inside.sum()
    # exponential with mean 1 m: mean 1, sd 1, plus the range noise
    assert err[inside].mean() == pytest.approx(1.0, abs=4 * math.sqrt(1 + np.mean(sigma[inside] ** 2)) / math.sqrt(n))
    assert abs(err[outside].mean()) < 4 * np.mean(sigma[outside]) / math.sqrt(outside.sum())
    assert np.mean(err[inside] > 0) > 0.75
    rssi_drop = r["rssi"][outside].mean() - r["rssi"][inside].mean()
    assert rssi_drop > 4  # 8 dB attenuation, partly offset by the distances differing


def test_rssi_follows_the_log_distance_model(office):
    """003 eq. 1: RSSI(d) = RSSI(1) - 10 n lg d + zeta: a regression recovers RSSI(1) and n."""
    sc, w, _, r = office
    d = true_distances(w, sc, r)
    slope, intercept = np.polyfit(np.log10(d), r["rssi"], 1)
    assert -slope / 10 == pytest.approx(sc.ranging.path_loss_exponent, abs=0.15)
    assert intercept == pytest.approx(sc.ranging.rssi_1m_dbm, abs=1.0)
    resid = r["rssi"] - (intercept + slope * np.log10(d))
    assert resid.std() == pytest.approx(math.hypot(sc.ranging.shadowing_db, 1 / math.sqrt(12)), rel=0.1)


def test_random_timeouts_at_the_scenario_rate(tmp_path):
    sc = variant(tmp_path, "office", "[ranging]\ntimeout_prob = 0.1\n")
    r = reports(run(sc)[1])
    timeouts = r["status"] == STATUS_TIMEOUT
    n = len(timeouts)
    assert timeouts.mean() == pytest.approx(0.1, abs=4 * math.sqrt(0.09 / n))


def test_corridor_range_errors_are_001s(tmp_path):
    """001 sect. 3.3: mean range error 0.66 m raw, 0.18 m after least-squares regression of
    (f, c_i). The corridor scenario's model reproduces both within 20 %."""
    sc = load_scenario("corridor")
    w, events = run(sc)
    r = reports(events)
    truth = true_distances(w, sc, r)
    raw = np.mean(np.abs(r["d"] - truth))
    residual = []
    for a in np.unique(r["anchor"]):
        m = r["anchor"] == a
        f, c = np.polyfit(truth[m], r["d"][m], 1)
        residual.append(r["d"][m] - (f * truth[m] + c))
    assert raw == pytest.approx(0.66, rel=0.2)
    assert np.mean(np.abs(np.concatenate(residual))) == pytest.approx(0.18, rel=0.2)


def multilaterate(anchors: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Least-squares position from ranges (Gauss-Newton from the anchors' centroid)."""
    x = anchors.mean(axis=0)
    for _ in range(15):
        diff = x - anchors
        rng = np.linalg.norm(diff, axis=1)
        x = x + np.linalg.lstsq(diff / rng[:, None], d - rng, rcond=None)[0]
    return x


def test_office_pure_wsn_error_is_of_000s_order(office):
    """000 sect. 3.3: pure WSN mean position error 0.64 m; the office calibration gives
    about that with a least-squares fix from each cycle's four ranges."""
    sc, w, _, r = office
    anchors = {a.id: (a.x, a.y) for a in sc.anchors}
    truth = w.truth(0, w.duration_ns)
    cycle = (r["t_us"] - 5000) // 100_000
    errors = []
    for c in np.unique(cycle):
        m = cycle == c
        fix = multilaterate(np.array([anchors[a] for a in r["anchor"][m]]), r["d"][m])
        t_mid = (r["t_us"][m].mean()) * 1000
        true = np.array([np.interp(t_mid, truth["t"], truth["x"]), np.interp(t_mid, truth["t"], truth["y"])])
        errors.append(np.linalg.norm(fix - true))
    assert np.mean(errors) == pytest.approx(0.64, rel=0.2)


def test_the_gateway_reports_only_exchanges_within_the_radio_range(tmp_path):
    """A tag driving away from anchor 1 and towards anchor 2 at 2 m/s: anchor 1's reports
    stop, and anchor 2's start, where the tag crosses radio_range_m, to the 0.2 m it moves
    per cycle; the reports within range are those of the same run without a range (the
    range draws nothing and changes no other exchange); seq stays gapless."""
    line = """
duration_s = 30.0
[area]
size = [60.0, 4.0]
[trajectory]
waypoints = [[2.0, 1.8], [58.0, 1.8]]
closed = false
speed_m_s = 2.0
accel_m_s2 = 1.0
alignment_s = 0.5
""" + anchors_toml([(1.0, 1.8), (59.0, 1.8)])
    limited = variant(tmp_path, "office", line + "[ranging]\nradio_range_m = 25.0\n", "limited")
    free = variant(tmp_path, "office", line, "free")
    w, events = run(limited)
    r = reports(events)
    d = true_distances(w, limited, r)
    step = limited.trajectory.speed_m_s * limited.ranging.cycle_ms / 1e3
    assert d.max() <= 25.0 + 1e-3
    one, two = r["anchor"] == 1, r["anchor"] == 2
    assert 25.0 - step - 1e-3 < d[one][-1] and 25.0 - step - 1e-3 < d[two][0]
    assert np.array_equal(r["seq"], np.arange(len(r["seq"])))
    wf, ef = run(free)
    rf = reports(ef)
    near = true_distances(wf, free, rf) <= 25.0
    assert near.sum() == len(r["seq"]) and 0 < near.sum() < len(near)
    for k in ("t_us", "anchor", "status", "rssi", "tau"):
        assert np.array_equal(r[k], rf[k][near])


def test_anchors_range_one_another_every_nth_cycle(tmp_path):
    """anchor_exchange_every_cycles = K: in cycles 0, K, 2K, ... each anchor ranges the next in
    slot order in turn (every ordered pair within m - 1 such cycles), its report naming the other
    anchor as the tag, the distance that pair's within the modelled noise and the RSSI eq. 1's;
    every other report is the same run's without them, byte for byte (they move no draw)."""
    every = 3
    peered = variant(tmp_path, "office", f"duration_s = 6.0\n[ranging]\nanchor_exchange_every_cycles = {every}\n",
                     "peered")
    plain = variant(tmp_path, "office", "duration_s = 6.0\n", "plain")
    r = reports(run(peered)[1])
    rp = reports(run(plain)[1])
    ids = [a.id for a in peered.anchors]
    cycle = (r["t_us"] - 5000) // 100_000
    among = cycle % every == 0
    assert np.array_equal(among, np.isin(r["tag"], ids))
    assert np.all(r["tag"][~among] == peered.tag.id)
    slot = np.array([ids.index(a) for a in r["anchor"]])
    expected = np.array(ids)[(slot + 1 + (cycle // every) % 3) % 4]
    assert np.array_equal(r["tag"][among], expected[among])
    assert {(a, t) for a, t in zip(r["anchor"][among], r["tag"][among])} == \
        {(a, b) for a in ids for b in ids if a != b}
    pos = {a.id: np.array(peered.anchor_position(a)) for a in peered.anchors}
    true = np.array([np.linalg.norm(pos[a] - pos[t]) for a, t in zip(r["anchor"][among], r["tag"][among])])
    rg = peered.ranging
    bias = np.array([{a.id: a.range_bias_m for a in peered.anchors}[a] for a in r["anchor"][among]])
    err = r["d"][among] - (rg.scale * true + bias)
    assert np.all(np.abs(err) < 5 * (rg.sigma0_m + rg.sigma_per_m * true))
    model = rg.rssi_1m_dbm - 10 * rg.path_loss_exponent * np.log10(true)
    assert np.all(np.abs(r["rssi"][among] - model) < 5 * rg.shadowing_db + 0.5)
    for k in ("seq", "t_us", "anchor", "tag", "status", "rssi", "tau"):
        assert np.array_equal(r[k][~among], rp[k][~among])


# anchor 2 out of line of sight and anchor 3's reports flagged, from the start (ledger marks)
FAULTS = """
[[faults]]
kind = "nlos"
anchor = 2
start_s = 0.5
end_s = 2.0

[[faults]]
kind = "range_value_error"
anchor = 3
"""


#: (base, overrides) by what each tries
TOGETHER = {
    "office": ("office", None),  # the seeds share the schedule's block: it draws nothing
    "jitter": ("office", "[ranging]\ncycle_jitter_ms = 2.0\n"),  # each seed its cycle starts
    "multipath": ("corridor", None),
    "faults": ("office", FAULTS),
    "outage": ("corridor-outage", '[[faults]]\nkind = "anchor_outage"\nanchor = 1\n'),
    "tags": ("office-convoy", None),  # three tags in turn
    "per-vehicle": ("office-convoy", '[ranging]\nnetwork = "per-vehicle"\n'),  # a port each
    "in-range": ("outage-bridging", None),  # wide reports and cycle jitter too
    "anchor-exchanges": ("rssi-centroid", None),  # and a radio range
}


@pytest.mark.parametrize("case", TOGETHER)
def test_networks_made_together_equal_each_made_alone(tmp_path, case):
    """World.make_together runs the nanoLOC networks of a block along one seed axis
    (NanolocNetwork.reports_together); every seed's events (bytes, t_ns and ledger marks) are
    those it makes alone, to the bit, and a world of another scenario (other networks) is made
    in the same call."""
    name, toml = TOGETHER[case]
    made = made_together(tmp_path, name, toml, "office", "nanoloc")
    if toml == FAULTS:
        assert any(e.marks for e in made[0] if e.port == "nanoloc")
