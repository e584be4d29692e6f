"""001's calibration on the emulated lab: the walk recovers the emulator's f and c_i, the
shipped step table and calibration file are what the command makes, and the calibrated
corridor's WSN error drops."""
import pytest

from navtwin.cli.main import main
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.host import calibration as cal
from navtwin.host import config as host_config
from navtwin.lab import calibration as lab
from navtwin.lab.evaluate import mean_ci

pytestmark = pytest.mark.slow  # emulated runs of 190 s and 127 s


@pytest.fixture(scope="module")
def walk():
    return lab.gateway_bytes("calibration")


def test_shipped_step_table_is_the_calibration_walks():
    shipped = cal.CALIBRATION_DIR / "corridor-steps.toml"
    assert shipped.read_text() == cal.steps_toml(lab.step_table("calibration"))
    assert cal.load_steps("corridor") == lab.step_table("calibration")


@pytest.mark.parametrize("seed", [None, 1, 2])
def test_calibration_recovers_the_emulators_f_and_c_within_its_intervals(walk, seed):
    """The scenario's f = 1.05 and c_i inside the fit's 95 % intervals; the range sd follows
    sigma(d) = 0.1 + 0.01 d within 15 % (a drift of 2 s and the sd's own bias are in it)."""
    sc = load_scenario("calibration")
    data = walk if seed is None else lab.gateway_bytes(sc, seed)
    result = lab.calibrate(data, cal.load_steps("corridor"), host_config.load("corridor"))
    c = result.calibration
    assert abs(c.scale - sc.ranging.scale) < c.scale_ci95
    for a in sc.anchors:
        assert abs(c.bias[a.id] - a.range_bias_m) < c.bias_ci95[a.id], a.id
    for d in (2.0, 8.0, 16.0):
        assert c.sigma(d) == pytest.approx(sc.ranging.sigma0_m + sc.ranging.sigma_per_m * d, rel=0.15)
    before, after = result.range_error_m
    assert before == pytest.approx(0.66, rel=0.2) and after == pytest.approx(0.18, rel=0.25)


def test_rerunning_the_command_reproduces_the_shipped_calibration(tmp_path, capsys):
    """host/calibrations/corridor.toml is `navtwin calibrate --scenario calibration`'s output."""
    out = tmp_path / "corridor.toml"
    assert main(["calibrate", "--scenario", "calibration", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "mean range error" in printed and "0.66 -> 0.18" in printed
    assert out.read_text() == (cal.CALIBRATION_DIR / "corridor.toml").read_text()


def test_calibrate_reads_a_recording_as_it_runs_a_scenario(tmp_path, walk, capsys):
    sc = load_scenario("calibration")
    with Emulation(sc, None, speed=None, ports=False, record=tmp_path / "rec") as emu:
        emu.run()
    assert lab.recorded_bytes(tmp_path / "rec") == walk
    assert main(["calibrate", str(tmp_path / "rec"), "--out", str(tmp_path / "c.toml")]) == 0
    capsys.readouterr()
    assert cal.load(tmp_path / "c.toml").bias == cal.load("corridor").bias


def test_with_the_calibration_the_corridors_wsn_error_drops():
    """The corridor's wsn track against the emulator's truth: mean and variance of the
    position error fall with the shipped calibration (figures: docs/emulator-models.md)."""
    config = host_config.load("corridor")
    before = lab.wsn_errors("corridor", 3, config, None)
    after = lab.wsn_errors("corridor", 3, config, config.calibration)
    assert after["mean"] < 0.9 * before["mean"]
    assert after["variance"] < before["variance"]


def test_the_table_keeps_its_columns_apart_whatever_the_figures(monkeypatch, tmp_path, capsys):
    """A variance of 1.5e6 m^2 ran into the figure before it ("0.4450383729339541500416")."""
    c = cal.load("corridor")
    wide = cal.Result(c, None, (6.98, 6.43), (10.874, 53.125), (0.445, 1500416.0), (1.0, 2.0), 160)
    monkeypatch.setattr(lab, "recorded_bytes", lambda directory: b"")
    monkeypatch.setattr(lab, "calibrate", lambda *a, **k: wide)
    assert main(["calibrate", "rec", "--out", str(tmp_path / "c.toml")]) == 0
    rows = {line[:30].strip(): line[30:].split() for line in capsys.readouterr().out.splitlines()}
    assert [float(v) for v in rows["WSN-only variance (m^2)"][:2]] == pytest.approx([0.445, 1.5e6])
    assert [float(v) for v in rows["WSN-only max error (m)"][:2]] == pytest.approx([10.874, 53.125])
    assert rows["mean range error (m)"] == ["6.980", "6.430", "0.66", "->", "0.18"]


def test_over_seeds_the_table_is_the_per_seed_runs_means_with_t_intervals(capsys):
    """`navtwin calibrate --seeds 1..3` is the mean of the three `--seed N` runs' figures, each
    with its 95 % t interval, and the paired after - before."""
    per = []
    for seed in (1, 2, 3):
        assert main(["calibrate", "--scenario", "calibration", "--seed", str(seed), "--out",
                     "/dev/null"]) == 0
        rows = {line[:30].strip(): line[30:].split() for line in capsys.readouterr().out.splitlines()}
        per.append({k: [float(v) for v in rows[k][:2]] for k in
                    ("mean range error (m)", "WSN-only max error (m)", "WSN-only variance (m^2)")})
    assert main(["calibrate", "--scenario", "calibration", "--seeds", "1..3"]) == 0
    table = {line[:50].strip(): line[50:].split() for line in capsys.readouterr().out.splitlines()[2:]}
    for one, many in (("mean range error (m)", "mean range error (m)"),
                      ("WSN-only max error (m)", "WSN-only max error at the points, in-sample (m)"),
                      ("WSN-only variance (m^2)", "WSN-only variance at the points, in-sample (m^2)")):
        cells = table[many]  # before ± h, after ± h, after - before ± h
        assert cells[1] == cells[4] == cells[7] == "±", many
        for col, values in ((0, [p[one][0] for p in per]), (3, [p[one][1] for p in per]),
                            (6, [p[one][1] - p[one][0] for p in per])):
            m, h = mean_ci(values)  # of the single runs' printed (rounded) figures
            assert float(cells[col]) == pytest.approx(m, abs=2e-3), (many, col)
            assert float(cells[col + 2]) == pytest.approx(h, abs=5e-3), (many, col)
    assert float(table["scale factor f"][0]) == pytest.approx(1.05, abs=0.02)
