"""003's path-loss model and its adaptive parameters (host.rssi, 003 eqs. 2-8)."""
from __future__ import annotations

import numpy as np
import pytest

from navtwin.host import rssi

ANCHORS = np.array([[0.0, 0.0, 2.5], [12.0, 0.0, 2.5], [12.0, 7.0, 2.5], [0.0, 9.0, 2.5]])
LAMBDA, N = -45.0, 2.7


def _heard(rng=None, sigma=0.0):
    """The anchors' readings of each other (eq. 2), with shadowing N(0, sigma^2)."""
    d = np.linalg.norm(ANCHORS[:, None] - ANCHORS[None], axis=2)
    np.fill_diagonal(d, 1.0)
    h = rssi.rssi(d, LAMBDA, N)
    if sigma:
        h = h + rng.normal(0.0, sigma, h.shape)
    np.fill_diagonal(h, np.nan)
    return h


def test_distance_inverts_the_model():
    d = np.array([0.5, 1.0, 3.0, 40.0])
    assert np.allclose(rssi.distance(rssi.rssi(d, LAMBDA, N), LAMBDA, N), d)
    assert rssi.rssi(1.0, LAMBDA, N) == LAMBDA and rssi.rssi(10.0, LAMBDA, N) == LAMBDA - 10 * N


def test_noise_free_readings_give_back_lambda_and_n_exactly():
    lam_i, n_i = rssi.anchor_parameters(ANCHORS, _heard())
    assert np.allclose(lam_i, LAMBDA, atol=1e-9) and np.allclose(n_i, N, atol=1e-9)
    lam, n = rssi.adaptive_parameters(lam_i, n_i, [-60.0, -52.0, -71.0, -66.0])
    assert lam == pytest.approx(LAMBDA, abs=1e-9) and n == pytest.approx(N, abs=1e-9)


def test_two_others_solve_eqs_3_and_4_exactly():
    three = ANCHORS[:3]
    h = _heard()[:3, :3]
    h[0, 1] += 2.0  # anchor 0's two readings alone fix its line
    lam_i, n_i = rssi.anchor_parameters(three, h)
    lg = np.log10([12.0, np.hypot(12.0, 7.0)])
    assert lam_i[0] - 10 * n_i[0] * lg[0] == pytest.approx(h[0, 1])
    assert lam_i[0] - 10 * n_i[0] * lg[1] == pytest.approx(h[0, 2])


def test_adjustment_factors_weigh_the_strongest_anchor_most():
    e = rssi.adjustment_factors([-50.0, -60.0, -70.0])
    assert e.tolist() == pytest.approx([0.0, 1 / 3, 2 / 3])  # eq. 5: sum of e over i >= 2 is 1
    w = (1 - e) / 2  # eqs. 6-7
    assert w.sum() == pytest.approx(1.0) and w[0] > w[1] > w[2]
    assert rssi.adaptive_parameters([1.0, 2.0, 3.0], [2.0, 3.0, 4.0], [-50.0, -60.0, -70.0]) == \
        pytest.approx((w @ [1, 2, 3], w @ [2, 3, 4]))
    # equal readings: eq. 5 is 0/0; equal weights
    assert rssi.adaptive_parameters([1.0, 2.0, 6.0], [2.0, 2.0, 2.0], [-60.0] * 3) == pytest.approx((3.0, 2.0))


def test_with_shadowing_the_estimator_is_unbiased_against_a_least_squares_fit():
    rng = np.random.default_rng(3)
    sigma, trials = 4.0, 2000
    est, rows, ys = [], [], []
    d = np.linalg.norm(ANCHORS[:, None] - ANCHORS[None], axis=2)
    off = ~np.eye(len(ANCHORS), dtype=bool)
    for _ in range(trials):
        h = _heard(rng, sigma)
        tag = rng.uniform([0, 0], [12, 9])
        tag_rssi = rssi.rssi(np.linalg.norm(ANCHORS[:, :2] - tag, axis=1), LAMBDA, N) + rng.normal(0, sigma, 4)
        est.append(rssi.adaptive_parameters(*rssi.anchor_parameters(ANCHORS, h), tag_rssi))
        rows.append(-10 * np.log10(d[off]))
        ys.append(h[off])
    # the cross-check: one dense least-squares fit of eq. 2 over every reading of every trial
    lg = np.concatenate(rows)
    (lam_fit, n_fit), *_ = np.linalg.lstsq(np.column_stack([np.ones_like(lg), lg]), np.concatenate(ys), rcond=None)
    assert lam_fit == pytest.approx(LAMBDA, abs=0.5) and n_fit == pytest.approx(N, abs=0.05)
    est = np.array(est)
    se = est.std(axis=0) / np.sqrt(trials)
    assert abs(est[:, 0].mean() - lam_fit) < 4 * se[0] + 0.1
    assert abs(est[:, 1].mean() - n_fit) < 4 * se[1] + 0.01


def test_an_anchor_hearing_fewer_than_two_others_is_refused():
    h = _heard()
    h[2, [0, 1]] = np.nan
    with pytest.raises(ValueError, match="anchor row 2 hears 1 other"):
        rssi.anchor_parameters(ANCHORS, h)


def test_anchor_readings_average_each_pair_and_fit_once_every_anchor_heard_two():
    """host.rssi.AnchorReadings: per ordered pair the mean in dBm (its fit equals eqs. 3-4 on
    the means, by a direct solve), None until each anchor heard two others; readings of
    anchors not in the layout are ignored; with shadowing the fit converges on (lambda, n)."""
    ids = (1, 2, 3, 4)
    readings = rssi.AnchorReadings(ids)
    h = _heard()
    for i in range(4):
        readings.add(ids[i], ids[(i + 1) % 4], h[i, (i + 1) % 4])
    assert readings.parameters(ANCHORS) is None
    readings.add(9, 1, -40.0)
    readings.add(1, 1, -40.0)
    for i in range(4):
        j = (i + 2) % 4
        readings.add(ids[i], ids[j], h[i, j] + 1.0)
        readings.add(ids[i], ids[j], h[i, j] - 3.0)
    means = readings.heard()
    assert means[0, 2] == pytest.approx(h[0, 2] - 1.0) and np.isnan(means[0, 3]) and readings.count.sum() == 12
    lam_i, n_i = readings.parameters(ANCHORS)
    for i in range(4):  # two others each: eqs. 3-4 solved directly
        j, k = (i + 1) % 4, (i + 2) % 4
        lg = np.log10([np.linalg.norm(ANCHORS[j] - ANCHORS[i]), np.linalg.norm(ANCHORS[k] - ANCHORS[i])])
        sol = np.linalg.solve([[1.0, -10 * lg[0]], [1.0, -10 * lg[1]]], [means[i, j], means[i, k]])
        assert (lam_i[i], n_i[i]) == pytest.approx(tuple(sol), abs=1e-9)
    rng = np.random.default_rng(5)
    many = rssi.AnchorReadings(ids)
    for _ in range(4000):  # a mean of 0.03 dB: the intercept, 1 m away from ~10 m, to ~0.3 dB
        noisy = _heard(rng, 2.0)
        for i in range(4):
            for j in range(4):
                if i != j:
                    many.add(ids[i], ids[j], noisy[i, j])
    lam_i, n_i = many.parameters(ANCHORS)
    assert np.allclose(lam_i, LAMBDA, atol=1.0) and np.allclose(n_i, N, atol=0.1)


def test_distance_sigma_is_the_spread_of_the_inverted_model_under_small_shadowing():
    # 0.5 dB: the log-normal distance is near-normal, its spread the first-order sigma
    rng = np.random.default_rng(4)
    for d, n in ((10.0, 2.0), (1500.0, 2.0), (300.0, 3.5)):
        readings = rssi.rssi(d, -45.0, n) + rng.normal(0.0, 0.5, 200_000)
        spread = rssi.distance(readings, -45.0, n).std()
        assert rssi.distance_sigma(d, 0.5, n) == pytest.approx(spread, rel=0.01), d
