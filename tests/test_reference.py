"""Restructuring changes no output: replay of each shipped scenario at three seeds gives
the reference estimates (fixtures/reference/estimates.npz, see tests/reference.py)."""
import numpy as np
import pytest

from . import reference


@pytest.fixture(scope="module")
def want():
    with np.load(reference.PATH) as f:
        return dict(f)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", reference.SCENARIOS)
@pytest.mark.parametrize("seed", reference.SEEDS)
def test_replay_gives_the_reference_estimates(want, scenario, seed):
    got = reference.arrays(reference.estimate_lines(scenario, seed))
    prefix = f"{scenario}/{seed}/"
    assert sorted(got) == sorted(k.removeprefix(prefix) for k in want if k.startswith(prefix))
    for key, value in got.items():
        ref = want[prefix + key]
        assert value.shape == ref.shape, key
        if value.dtype == bool:
            assert (value == ref).all(), key
        else:
            np.testing.assert_allclose(value, ref, rtol=1e-9, atol=1e-12, equal_nan=True,
                                       err_msg=prefix + key)
