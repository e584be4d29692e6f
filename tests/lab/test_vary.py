"""Parameter sweeps (lab.vary): a scenario key over values, crossed with the seeds."""
from __future__ import annotations

import pytest

from navtwin.cli.main import main
from navtwin.emulator.scenario import load_scenario
from navtwin.lab import sweep
from navtwin.lab.vary import Vary, VaryError, label, variant

from ..helpers import cli_error


def test_values_are_toml_and_a_range_ends_where_it_says():
    assert Vary.parse("ranging.sigma0_m=0.1..0.5:0.1").values == (0.1, 0.2, 0.3, 0.4, 0.5)
    v = Vary.parse(" imu.grade = adis16350, tactical ,'x y'")
    assert v.key == "imu.grade" and v.values == ("adis16350", "tactical", "x y")
    assert Vary.parse("a.b=1,2.5,true").values == (1, 2.5, True)
    assert [label(x) for x in (1, 2.5, True, "s")] == ["1", "2.5", "true", "s"]
    assert Vary.parse("k=0.1234567,0.1234568").values == (0.1234567, 0.1234568)  # two values
    for bad, what in (("ranging.sigma0_m", "not KEY=VALUES"), ("k=1,1", "twice"),
                      ("k=0.5..0.1:0.1", "A <= B"), ("k=0..1:0", "STEP > 0"),
                      ("k=0..1000:1", "at most 100"), ("k=1,,2", "empty value")):
        with pytest.raises(VaryError, match=what) as e:
            Vary.parse(bad)
        assert "\n" not in str(e.value)


def test_a_variant_is_the_scenario_with_its_key_set_and_checked():
    office = load_scenario("office")
    sc = variant(office, "ranging.sigma0_m", 0.6)
    assert "sigma0_m = 0.6" in sc.to_toml() and "sigma0_m = 0.3" in office.to_toml()
    assert sc.to_toml().replace("sigma0_m = 0.6", "sigma0_m = 0.3") == office.to_toml()
    sc = variant(office, "anchors.2.range_bias_m", 0.0)  # an array of tables by index
    assert [a.range_bias_m for a in sc.anchors] == [0.35, 0.3, 0.0, 0.3]
    for key, value, what in (("ranging.nope", 1, "no such key"), ("radio.x", 1, "no table radio"),
                             ("anchors.9.x", 1.0, "0 to 3"), ("ranging", 1, "table or array"),
                             ("ranging.sigma0_m", -1.0, "sigma0_m")):
        with pytest.raises(VaryError, match=what):
            variant(office, key, value)


def test_each_value_gives_the_cells_of_its_own_sweep_and_the_range_noise_shows(tmp_path):
    """A parameter sweep's cells are those of a plain sweep of each value's scenario; the
    WSN track's error grows with the ranging noise it is given (0.1 against 0.6 m)."""
    vary = Vary.parse("ranging.sigma0_m=0.1,0.6")
    result = sweep.run("office", [1, 2, 3], ["wsn"], duration=12.0, serial=True, vary=vary,
                       out=tmp_path / "p")
    assert [(r["variant"], r["seed"]) for r in result.rows] == [
        (v, s) for v in ("0.1", "0.6") for s in (1, 2, 3)]
    office = load_scenario("office")
    for value in vary.values:
        alone = sweep.run(variant(office, vary.key, value), [1, 2, 3], ["wsn"], duration=12.0,
                          serial=True).rows
        mine = [r for r in result.rows if r["variant"] == label(value)]
        assert [{**r, "variant": None} for r in mine] == alone
    means = {v: s["filters"]["wsn"]["mean"][0]
             for v, s in sweep.summarise_values(result.rows, ["wsn"]).items()}
    assert means["0.6"] > 2 * means["0.1"]
    again = sweep.run("office", [1, 2, 3], ["wsn"], duration=12.0, serial=True, vary=vary,
                      out=tmp_path / "p")
    assert again.tasks == 0 and again.rows == result.rows
    with pytest.raises(sweep.SweepError, match="another parameter sweep"):
        sweep.run("office", [1], ["wsn"], duration=12.0, serial=True, out=tmp_path / "p",
                  vary=Vary.parse("ranging.sigma0_m=0.2"))


def test_the_command_prints_a_table_per_value_then_the_values_side_by_side(capsys, tmp_path):
    assert main(["sweep", "--seeds", "1..2", "--filters", "wsn", "--duration", "8", "--serial",
                 "--quiet", "--vary", "ranging.sigma0_m=0.1,0.6", "--out",
                 str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "ranging.sigma0_m = 0.1:\nfilter" in out and "ranging.sigma0_m = 0.6:\nfilter" in out
    assert "mean error (m) by ranging.sigma0_m" in out
    line = cli_error(capsys, "sweep", "--seeds", "1", "--serial", "--vary", "ranging.nope=1")
    assert "ranging.nope" in line and "no such key" in line
