"""Restructuring changes no output: replay of each shipped scenario at three seeds gives
the reference estimates (fixtures/reference/estimates.npz, see tests/reference.py)."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from . import reference

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def want():
    with np.load(reference.PATH) as f:
        return dict(f)


def assert_reference(want, got, scenario, seed):
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


@pytest.mark.slow
@pytest.mark.parametrize("scenario", reference.SCENARIOS)
@pytest.mark.parametrize("seed", reference.SEEDS)
def test_replay_gives_the_reference_estimates(want, scenario, seed):
    got = reference.arrays(reference.estimate_lines(scenario, seed))
    assert_reference(want, got, scenario, seed)


@pytest.mark.slow
def test_other_blas_kernels_give_the_reference_estimates(want, tmp_path):
    """Under OpenBLAS's AVX (Sandybridge) kernels, which round products differently in the last
    bit, the same estimates: corridor-outage, where three anchors leave TDOA mirror positions
    that fit alike, once chose between them by that bit. The kernel is chosen when numpy is
    imported, so in a subprocess (elsewhere than OpenBLAS on x86-64 the variable is ignored)."""
    got = tmp_path / "got.npz"
    code = ("import sys, numpy as np; from tests import reference; np.savez(sys.argv[1], "
            "**reference.arrays(reference.estimate_lines('corridor-outage', 1)))")
    subprocess.run([sys.executable, "-c", code, str(got)], cwd=ROOT, check=True, timeout=600,
                   env={**os.environ, "OPENBLAS_CORETYPE": "Sandybridge"})
    with np.load(got) as f:
        assert_reference(want, dict(f), "corridor-outage", 1)
