"""The flicker bias (emulator.bias): the weights' derivation holds, the sum of Gauss-Markov
terms is flat at the floor over 1 .. 3000 s, its held terms step on their grids (a sweep's
seeds together as each alone, to the bit) and keep the curve (the closed form against a dense
solve over every phase), and a simulated bias gives back its floor (allantools' overlapping
Allan deviation as the oracle)."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from navtwin.emulator.bias import (FLICKER_BAND_S, FLICKER_TAUS_S, FlickerBias, RateRandomWalk,
                                   _held_allan_variance, flicker_allan_variance,
                                   flicker_term_variance, gm_allan_variance, hold_samples)

TS = 1 / 819.2  # the ADIS16350's default sample period


def test_one_term_matches_its_limits_and_the_integral_is_2_ln_2():
    """A(x) -> 2x/3 below tau and 2/x above it; int A(x) dx/x = 2 ln 2 (the weights' constant)."""
    assert gm_allan_variance(1e-4, 1.0) == pytest.approx(2e-4 / 3, rel=1e-3)
    assert gm_allan_variance(1e4, 1.0) == pytest.approx(2e-4, rel=1e-3)
    assert gm_allan_variance(0.049, 1.0) == pytest.approx(gm_allan_variance(0.051, 1.0), rel=0.05)
    integral = quad(lambda u: float(gm_allan_variance(math.exp(u), 1.0)), -40, 40, limit=1000)[0]
    assert integral == pytest.approx(2 * math.log(2), rel=1e-6)


def test_the_sum_is_flat_at_the_floor_over_the_band():
    t = np.logspace(*np.log10(FLICKER_BAND_S), 400)
    adev = np.sqrt(flicker_allan_variance(t, 1.0))
    assert adev.min() > 0.985 and adev.max() < 1.001
    assert len(FLICKER_TAUS_S) == 13 and FLICKER_TAUS_S[1] / FLICKER_TAUS_S[0] == pytest.approx(10 ** 0.5)
    held = np.sqrt(flicker_allan_variance(np.logspace(*np.log10(FLICKER_BAND_S), 40), 1.0, TS))
    assert held.min() > 0.985 and held.max() < 1.001


def test_holding_the_slow_terms_keeps_the_allan_curve():
    """The samples' exact curve, holds and all, against the continuous terms' (the design):
    within 1 % at 10 ms (8 samples) and 0.1 % from 0.1 s to 3000 s."""
    t = np.array([0.01, 0.1, 1.0, 10.0, 100.0, 1000.0, 3000.0])
    ratio = np.sqrt(flicker_allan_variance(t, 1.0, TS) / flicker_allan_variance(t, 1.0))
    assert ratio[0] == pytest.approx(1.0, abs=1e-2) and ratio[1:] == pytest.approx(1.0, abs=1e-3)
    assert hold_samples(TS).tolist()[:3] == [3, 9, 30]  # tau_k / (8 ts), at least 1


@pytest.mark.parametrize("m, phi, n", [(1, 0.9, 7), (3, 0.8, 5), (4, 0.6, 2), (5, 0.7, 13), (6, 0.5, 1)])
def test_the_held_terms_closed_form_is_the_dense_solve_over_every_phase(m, phi, n):
    """AVAR of a term held for m samples (a GM of phi per step on its grid), at n samples:
    the closed form against c^T Sigma c / (2 n^2) with the samples' covariance matrix built
    for each phase of the grid and averaged (c: -1 on the first n samples, +1 on the next)."""
    i = np.arange(2 * n)
    c = np.where(i < n, -1.0, 1.0)
    dense = np.mean([c @ phi ** np.abs((i[:, None] + p) // m - (i[None, :] + p) // m) @ c
                     for p in range(m)]) / (2 * n * n)
    assert _held_allan_variance(np.array([float(n)]), m, phi)[0] == pytest.approx(dense, rel=1e-12)


def test_the_held_terms_step_on_their_grid_across_blocks():
    """FlickerBias against a plain loop over the samples on the same draws: each term steps
    at the samples j = 0 mod m_k, counted from the first, and holds in between, whatever
    the blocks (the draws of a block: its steps, term by term)."""
    ts, floor = 0.05, 2.0
    got = FlickerBias(floor, ts, np.random.default_rng(5))
    rng = np.random.default_rng(5)
    hold = hold_samples(ts)
    phi = np.exp(-hold * ts / FLICKER_TAUS_S)
    sigma = math.sqrt(flicker_term_variance(floor))
    state = sigma * rng.standard_normal((len(hold), 3))
    j = 0
    for n in (1, 7, 500, 3, 9000, 2500, 17):
        steps = [[i for i in range(j, j + n) if i % m == 0] for m in hold]
        w = iter(rng.standard_normal((sum(map(len, steps)), 3)))
        at = {}
        for k, ks in enumerate(steps):
            for i in ks:
                at.setdefault(i, []).append((k, next(w)))
        want = []
        for i in range(j, j + n):
            for k, x in at.get(i, ()):
                state[k] = phi[k] * state[k] + sigma * math.sqrt(1 - phi[k] ** 2) * x
            want.append(state.sum(axis=0))
        assert got.next(n) == pytest.approx(np.array(want), rel=0, abs=1e-12)
        j += n
    assert sum(hold < j) >= 9  # the slow terms stepped too


@pytest.mark.parametrize("ts", [TS, 0.05])
def test_seeds_together_are_each_alone_to_the_bit(ts):
    """FlickerBias.together on three seeds gives each seed's bias of FlickerBias.next alone
    (one seed), equal to the bit, over blocks of any length starting at any phase of the
    holds: a term's scan runs over its own steps, whatever the seeds and the other terms."""
    made = [FlickerBias(2.0, ts, np.random.default_rng(s)) for s in (1, 2, 3)]
    alone = [FlickerBias(2.0, ts, np.random.default_rng(s)) for s in (1, 2, 3)]
    for n in (1, 7, 819, 820, 3, 9000, 2, 2500, 17):
        assert np.array_equal(FlickerBias.together(made, n), [b.next(n) for b in alone])
    assert all(np.array_equal(a.state, b.state) for a, b in zip(made, alone))


def test_simulated_flicker_and_rate_random_walk_give_back_their_allan_curves():
    """6 h at 20 Hz, three axes: the overlapping Allan deviation pooled over the axes at 1, 10
    and 100 s within 8 % of the samples' exact curve (the terms of 0.95 s and up held). Over five seeds its spread (1 sigma) is
    0.2, 0.3 and 0.8 % at those taus (4 % for one axis at 100 s): 8 % is far outside it."""
    allantools = pytest.importorskip("allantools")
    ts, n, floor = 0.05, 432_000, 2.0
    flicker = FlickerBias(floor, ts, np.random.default_rng(1))
    b = np.concatenate([flicker.next(n // 4) for _ in range(4)])  # blocks carry the state
    taus = np.array([1.0, 10.0, 100.0])
    avar = np.mean([allantools.oadev(b[:, axis], rate=1 / ts, data_type="freq", taus=taus)[1] ** 2
                    for axis in range(3)], axis=0)
    assert np.sqrt(avar) == pytest.approx(floor * np.sqrt(flicker_allan_variance(taus, 1.0, ts)), rel=0.08)
    rrw = RateRandomWalk(0.5, ts, np.random.default_rng(2)).next(n)
    got_taus, adev, *_ = allantools.oadev(rrw[:, 0], rate=1 / ts, data_type="freq", taus=taus)
    assert adev == pytest.approx(0.5 * np.sqrt(got_taus / 3), rel=0.1)


def test_the_prefix_scan_is_the_recursion():
    """first_order's log2(n) numpy steps give y_j = phi y_j-1 + x_j from y_-1, per seed, as
    scipy's lfilter does (to rounding), for slow and fast terms and a block of odd length."""
    from scipy.signal import lfilter

    from navtwin.emulator.bias import first_order

    rng = np.random.default_rng(3)
    for p in np.exp(-1 / 819.2 / FLICKER_TAUS_S):
        x, before = rng.standard_normal((819, 4, 3)), rng.standard_normal((4, 3))
        got = first_order(p, x, before)
        for seed in range(4):
            want, _ = lfilter([1.0], [1.0, -p], x[:, seed], axis=0, zi=(p * before[seed])[None, :])
            assert np.allclose(got[:, seed], want, rtol=0, atol=1e-11)
