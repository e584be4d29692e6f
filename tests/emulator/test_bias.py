"""The flicker bias (emulator.bias): the weights' derivation holds, the sum of Gauss-Markov
terms is flat at the floor over 1 .. 3000 s, and a simulated bias gives back its floor
(allantools' overlapping Allan deviation as the oracle)."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from navtwin.emulator.bias import (FLICKER_BAND_S, FLICKER_TAUS_S, FlickerBias, RateRandomWalk,
                                   flicker_allan_variance, gm_allan_variance)


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


def test_simulated_flicker_and_rate_random_walk_give_back_their_allan_curves():
    """6 h at 20 Hz, three axes: the overlapping Allan deviation pooled over the axes at 1, 10
    and 100 s within 8 % of the sum's exact curve. Over five seeds its spread (1 sigma) is
    0.2, 0.3 and 0.8 % at those taus (4 % for one axis at 100 s): 8 % is far outside it."""
    allantools = pytest.importorskip("allantools")
    ts, n, floor = 0.05, 432_000, 2.0
    flicker = FlickerBias(floor, ts, np.random.default_rng(1))
    b = np.concatenate([flicker.next(n // 4) for _ in range(4)])  # blocks carry the state
    taus = np.array([1.0, 10.0, 100.0])
    avar = np.mean([allantools.oadev(b[:, axis], rate=1 / ts, data_type="freq", taus=taus)[1] ** 2
                    for axis in range(3)], axis=0)
    assert np.sqrt(avar) == pytest.approx(floor * np.sqrt(flicker_allan_variance(taus, 1.0)), rel=0.08)
    rrw = RateRandomWalk(0.5, ts, np.random.default_rng(2)).next(n)
    got_taus, adev, *_ = allantools.oadev(rrw[:, 0], rate=1 / ts, data_type="freq", taus=taus)
    assert adev == pytest.approx(0.5 * np.sqrt(got_taus / 3), rel=0.1)


def test_the_prefix_scan_is_the_recursion():
    """first_order's log2(n) numpy steps give y_j = phi y_j-1 + x_j from y_-1, per term, as
    scipy's lfilter does (to rounding), over slow and fast terms and a block of odd length."""
    from scipy.signal import lfilter

    from navtwin.emulator.bias import first_order

    rng = np.random.default_rng(3)
    phi = np.exp(-1 / 819.2 / FLICKER_TAUS_S)
    x, before = rng.standard_normal((len(phi), 819, 3)), rng.standard_normal((len(phi), 3))
    got = first_order(phi, x, before)
    for k, p in enumerate(phi):
        want, _ = lfilter([1.0], [1.0, -p], x[k], axis=0, zi=(p * before[k])[None, :])
        assert np.allclose(got[k], want, rtol=0, atol=1e-11)
