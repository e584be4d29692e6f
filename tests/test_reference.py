"""Restructuring changes no output: replay of each shipped scenario at three seeds gives
the reference estimate lines (fixtures/reference/estimates.json, see tests/reference.py)."""
import json

import pytest

from . import reference


@pytest.mark.slow
@pytest.mark.parametrize("scenario", reference.SCENARIOS)
@pytest.mark.parametrize("seed", reference.SEEDS)
def test_replay_gives_the_reference_estimates(scenario, seed):
    want = json.loads(reference.PATH.read_text())[scenario][str(seed)]
    got = reference.digest(reference.estimate_lines(scenario, seed))
    assert got["filters"] == want["filters"]  # names the filter whose lines moved
    assert got == want
