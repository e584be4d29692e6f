"""The schema's maps keyed by id (issue 18 item 5): ``range_bias_m = {1 = 0.3}`` in a host
config, ``[bias_m]`` in a calibration file, checked as every other key is, one line each."""
from __future__ import annotations

from dataclasses import dataclass

import pytest

from navtwin.common.schema import Invalid, between, build, key, rows, value


@dataclass(frozen=True)
class Biases:
    bias_m: dict[int, float] | None = key(None, "m", "per anchor id", between(-5, 5),
                                          ids=("anchor", (1, 254)))


def test_a_map_is_built_with_integer_ids_and_checked_values():
    assert build(Biases, {"bias_m": {"1": 0.3, "12": -1}}).bias_m == {1: 0.3, 12: -1.0}
    assert build(Biases, {}).bias_m is None
    assert rows(Biases)[0][:4] == ("bias_m", "m", "none", "in [-5, 5]")


@pytest.mark.parametrize("data, line", [
    ({"bias_m": 0.3}, "bias_m must be a table of anchor id = value like {1 = 0.3, 2 = 0.25} "
                      "(got 0.3); write it so"),
    ({"bias_m": {"x": 0.3}}, "bias_m names anchor 'x', which is not an anchor id (1..254); name "
                             "each anchor by its id"),
    ({"bias_m": {"255": 0.3}}, "bias_m names anchor '255', which is not an anchor id"),
    ({"bias_m": {"2": "near"}}, "bias_m 2 must be a number (got 'near'); write it like 0.5"),
    ({"bias_m": {"2": 9.0}}, "bias_m 2 must be in [-5, 5] (got 9 m); use a value from -5 to 5"),
    ({"bias_m": {"2": float("nan")}}, "bias_m 2 must be a finite number"),
])
def test_a_bad_map_is_one_line_naming_the_entry(data, line):
    with pytest.raises(Invalid) as e:
        build(Biases, data, (("filters", 0),))
    assert str(e.value).startswith("[filters] " + line)


def test_a_single_value_is_checked_as_a_key_is():
    assert value(3, int, "--seeds", between(1, 9)) == 3
    with pytest.raises(Invalid, match=r"^--seeds must be in \[1, 9\] \(got 12\)"):
        value(12, int, "--seeds", between(1, 9))
    with pytest.raises(Invalid, match=r"^x must be a finite number"):
        value(float("inf"), float, "x")
