"""The Fresnel integrals in numpy are scipy.special.fresnel's floats to the bit: the golden
recordings were made with scipy, and the clothoid corners of every scenario use them. scipy is
the oracle here only."""
import numpy as np
import pytest

from navtwin.emulator.fresnel import HUGE_X, SMALL_X2, fresnel

SMALL_EDGE = SMALL_X2 ** 0.5  # 1.6: the power series below, the auxiliary functions above


def _arguments() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(17)
    edges = np.array([SMALL_EDGE, HUGE_X, 1.0, 2.0, 0.5, 1e-300, 5e-324, 1e150, 1.3e154])
    edges = np.concatenate([edges, np.nextafter(edges, 0.0), np.nextafter(edges, np.inf)])
    return {
        "dense": np.linspace(-12.0, 12.0, 480_001),  # through 0, both edges of the series
        "small": rng.uniform(-SMALL_EDGE, SMALL_EDGE, 100_000),
        "mid": rng.uniform(SMALL_EDGE, 200.0, 100_000) * rng.choice([-1.0, 1.0], 100_000),
        "large": rng.uniform(200.0, HUGE_X, 100_000),
        "huge": np.exp(rng.uniform(np.log(HUGE_X), np.log(1.3e154), 100_000)),
        "tiny": np.exp(rng.uniform(-745.0, 0.0, 100_000)) * rng.choice([-1.0, 1.0], 100_000),
        "edges": np.concatenate([edges, -edges, [0.0, -0.0, np.inf, -np.inf]]),
    }


@pytest.mark.parametrize("which", list(_arguments()))
def test_fresnel_is_scipys_to_the_bit(which):
    from scipy.special import fresnel as scipy_fresnel

    x = _arguments()[which]
    want, got = scipy_fresnel(x), fresnel(x)
    for name, w, g in zip("SC", want, got):
        differ = w.view(np.int64) != g.view(np.int64)
        assert not differ.any(), f"{name}({x[differ][:3]}): {g[differ][:3]} != {w[differ][:3]}"


def test_fresnel_is_nan_where_scipys_is():
    """NaN in, and |x| >= 1.35e154 (x^2 overflows): NaN, as scipy gives (the sign bit of a
    NaN is not a value: scipy's comes from the x86 'default NaN', numpy's need not)."""
    from scipy.special import fresnel as scipy_fresnel

    x = np.array([np.nan, -np.nan, 1.4e154, -1e300, np.finfo(float).max])
    for w, g in zip(scipy_fresnel(x), fresnel(x)):
        assert np.isnan(w).all() and np.isnan(g).all()


def test_scalar_argument():
    from scipy.special import fresnel as scipy_fresnel

    assert [float(v) for v in fresnel(0.75)] == [float(v) for v in scipy_fresnel(0.75)]
