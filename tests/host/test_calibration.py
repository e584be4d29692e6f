"""001's range calibration on the host (host.calibration): the least-squares fit on ranges of
known law, the file and its one-line errors, the host config's [calibration] and the
estimator's use of it."""
import dataclasses
import math

import numpy as np
import pytest

from navtwin.host import calibration as cal
from navtwin.host import config as host_config
from navtwin.host.config import ConfigError
from navtwin.host.estimator import Estimator
from navtwin.host.measurements import Exchange
from navtwin.protocols.nanoloc import SPEED_OF_LIGHT, STATUS_COMPLETE, build_report

from ..helpers import CORRIDOR_ANCHORS, run_cli

REPLY = 100_000_000  # ps
F, C = 1.05, {1: 0.25, 2: 0.18, 3: 0.30, 4: 0.22}


def walk(n_steps=31, per=20):
    """A step table along y = 0.4 and 0.1 s cycles of 4 exchanges at each rest."""
    steps = tuple(cal.Step(x=1.5 - 0.6 * k, y=0.4, start_s=10.0 * k, end_s=10.0 * k + 0.1 * per)
                  for k in range(n_steps))
    return cal.StepTable(steps=steps, exchanges=per)


def gateway_stream(table, sigma, rng, scale=F, bias=C) -> bytes:
    """Reports whose four-timestamp distance is f d + c_i + N(0, sigma(d)^2) at every rest."""
    out, seq = [], 0
    for step in table.steps:
        for k in range(table.exchanges):
            for a, (x, y, z) in CORRIDOR_ANCHORS.items():
                d = math.dist((step.x, step.y), (x, y))
                reported = scale * d + bias[a] + sigma(d) * rng.standard_normal()
                x = round(2 * reported / SPEED_OF_LIGHT * 1e12)  # c (tau1 - tau2 + tau3 - tau4) / 4
                t_us = round((step.start_s + 0.1 * k + 0.02 * (a - 1)) * 1e6)
                out.append(build_report(seq=seq % 65536, t_us=t_us, anchor=a, tag=16,
                                        status=STATUS_COMPLETE, rssi=-60,
                                        tau=(REPLY + x, REPLY, REPLY + x, REPLY)))
                seq += 1
    return b"".join(out)


def test_fit_recovers_f_c_and_sigma_of_a_known_law():
    """White noise sigma(d) = 0.1 + 0.01 d: f and every c_i inside their 95 % intervals, the
    sd polynomial within 10 % of the law over the walk, residual error about sigma's mean."""
    table = walk()
    law = lambda d: 0.1 + 0.01 * d
    r = cal.ranges(gateway_stream(table, law, np.random.default_rng(3)))
    result = cal.fit(r, table, CORRIDOR_ANCHORS)
    c = result.calibration
    assert abs(c.scale - F) < c.scale_ci95 and c.scale_ci95 < 0.01
    for a in CORRIDOR_ANCHORS:
        assert abs(c.bias[a] - C[a]) < c.bias_ci95[a], a
    d = np.linspace(1.0, 18.0, 20)
    assert np.allclose(c.sigma(d), law(d), rtol=0.1)
    assert result.exchanges == 31 * 4 * 20
    before, after = result.range_error_m
    assert before > 0.5 and after == pytest.approx(np.mean(law(d)) * math.sqrt(2 / math.pi), rel=0.25)
    assert result.wsn_variance_m2[1] < result.wsn_variance_m2[0]


def test_fit_uses_only_the_windows_and_the_first_exchanges():
    """Ranges outside every rest are ignored (the tag moving); at most `exchanges` per anchor."""
    table = walk(per=20)
    data = gateway_stream(table, lambda d: 0.0, np.random.default_rng(1))
    moving = gateway_stream(dataclasses.replace(table, steps=tuple(
        dataclasses.replace(s, start_s=s.start_s + 5.0, end_s=s.end_s + 5.0) for s in table.steps)),
        lambda d: 0.0, np.random.default_rng(1), scale=1.3, bias={a: 2.0 for a in CORRIDOR_ANCHORS})
    c = cal.fit(cal.ranges(data + moving), dataclasses.replace(table, exchanges=5),
                CORRIDOR_ANCHORS).calibration
    assert c.scale == pytest.approx(F, abs=1e-4)  # taus are whole picoseconds: 0.15 mm
    assert all(c.bias[a] == pytest.approx(C[a], abs=1e-3) for a in CORRIDOR_ANCHORS)


def test_file_round_trip_and_sigma_clamps_to_its_span(tmp_path):
    c = cal.Calibration(scale=1.05, bias={1: 0.25, 2: -0.1}, sigma_coefficients=(0.1, 0.01, -1e-4),
                        sigma_span_m=(0.6, 20.0), scale_ci95=0.01, bias_ci95={1: 0.05, 2: 0.04})
    path = tmp_path / "c.toml"
    path.write_text(c.to_toml("a header\nof two lines"))
    back = cal.load(path)
    assert dataclasses.replace(back, source="") == c
    assert back.sigma(50.0) == back.sigma(20.0) and back.sigma(0.0) == back.sigma(0.6)
    assert back.correct(2, 5.0) == pytest.approx(5.1 / 1.05)
    assert cal.load("corridor").bias.keys() == {1, 2, 3, 4}  # a shipped one by name


GOOD = cal.Calibration(scale=1.05, bias={1: 0.25}, sigma_coefficients=(0.1,), sigma_span_m=(0.6, 20.0)).to_toml()


@pytest.mark.parametrize("text, problem", [
    ("scale = 1.0", 'format is not "navtwin-calibration"'),
    (GOOD.replace("version = 1", "version = 7"), "version 7 is not 1"),
    (GOOD.replace("scale = 1.05", "scale = 9.0"), "scale must be"),
    (GOOD.replace("1 = 0.25", "nine = 0.25", 1), "is not an anchor id"),
    (GOOD.replace("1 = 0.25", "1 = 99.0", 1), "bias_m 1 must be in [-5, 5]"),
    (GOOD.replace("span_m = [0.6, 20.0]", "span_m = [20.0, 0.6]"), "span_m must be"),
    (GOOD.replace("[sigma]", "[sigmas]"), "unknown key 'sigmas'"),
    (GOOD + "[[", "not valid TOML"),
    (GOOD.replace("1 = 0.25", "0 = 0.25", 1), "bias_m names anchor '0', which is not an anchor id (1..254)"),
    (GOOD.replace("1 = 0.25", '1 = "x"', 1), "bias_m 1 must be a number (got 'x')"),
    (GOOD.replace("[bias_m]\n1 = 0.25\n", "[bias_m]\n"), "bias_m is empty"),
    (GOOD.replace("[bias_ci95_m]", "[bias_ci95_m]\n3 = 11.0"), "bias_ci95_m 3 must be in [0, 10]"),
    (GOOD.replace("coefficients = [0.1]", "coefficients = []"), "coefficients must hold 1 to 8"),
    (GOOD.replace("coefficients = [0.1]", "coefficients = [1000.0]"), "coefficients elements must be in [-100, 100]"),
])
def test_bad_calibration_file_is_one_line(tmp_path, text, problem):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(cal.CalibrationError) as e:
        cal.load(path)
    assert problem in str(e.value) and "\n" not in str(e.value) and str(path) in str(e.value)


def test_host_with_a_bad_calibration_exits_2_with_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("scale = 2\n")
    code, _, err = run_cli(capsys, "host", "--nanoloc", "/dev/null", "--calibration", str(bad))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--calibration" in err
    assert "format is not" in err
    code, _, err = run_cli(capsys, "host", "--nanoloc", "/dev/null", "--calibration",
                           str(tmp_path / "none.toml"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "cannot read" in err


def test_calibrate_with_a_bad_step_table_exits_2_with_one_line(tmp_path, capsys):
    steps = tmp_path / "steps.toml"
    steps.write_text("[[steps]]\nx = 1.0\ny = 0.0\nstart_s = 5.0\nend_s = 4.0\n")
    code, _, err = run_cli(capsys, "calibrate", str(tmp_path), "--steps", str(steps))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "end_s" in err


def test_host_config_calibration_section(tmp_path):
    cfg = host_config.load("corridor")
    assert cfg.calibration is not None and cfg.calibration.bias.keys() == {1, 2, 3, 4}
    back = host_config.from_dict(cfg.to_dict())  # a recording's meta: the calibration inline
    assert dataclasses.replace(back.calibration, source="") == dataclasses.replace(cfg.calibration, source="")
    text = (host_config.CONFIG_DIR / "corridor.toml").read_text()
    (tmp_path / "mine.toml").write_text(cal.load("corridor").to_toml())
    (tmp_path / "lab.toml").write_text(text.replace('file = "corridor"', 'file = "mine.toml"'))
    assert host_config.load(tmp_path / "lab.toml").calibration.scale == cfg.calibration.scale
    (tmp_path / "both.toml").write_text(text.replace("alignment_s = 5.0", "alignment_s = 5.0\nrange_scale = 1.1"))
    with pytest.raises(ConfigError, match="beside \\[calibration\\]"):
        host_config.load(tmp_path / "both.toml")
    (tmp_path / "missing.toml").write_text(text.replace('file = "corridor"', 'file = "no.toml"'))
    with pytest.raises(ConfigError, match="cannot read"):
        host_config.load(tmp_path / "missing.toml")


def test_estimator_holds_the_calibration_and_corrects_as_range_scale_and_bias_do():
    """est.calibration is the loaded object (None without); the estimates equal those of
    the same f and c_i given as range_scale and range_bias_m."""
    cfg = host_config.load("corridor")
    c = cfg.calibration
    calibrated = Estimator(cfg.estimator_config())
    assert calibrated.calibration is c
    plain_cfg = dataclasses.replace(cfg, calibration=None)
    assert Estimator(plain_cfg.estimator_config()).calibration is None
    manual = dataclasses.replace(plain_cfg, range_bias_m=dict(c.bias),
                                 tuning=dataclasses.replace(cfg.tuning, range_scale=c.scale))
    by_hand = Estimator(manual.estimator_config(("wsn",)))
    calibrated = Estimator(cfg.estimator_config(("wsn",)))
    rng = np.random.default_rng(2)
    out_a, out_b = [], []
    for k in range(50):
        for a, (x, y, _) in CORRIDOR_ANCHORS.items():
            d = c.scale * math.dist((0.0, 0.0), (x, y)) + c.bias[a] + 0.05 * rng.standard_normal()
            rec = Exchange(0.1 * k + 0.025 * a, a, d)
            out_a += calibrated.feed(rec)
            out_b += by_hand.feed(rec)
    assert out_a and [(e.x, e.y) for e in out_a] == [(e.x, e.y) for e in out_b]
    uncorrected = Estimator(plain_cfg.estimator_config(("wsn",)))
    out_c = [e for k in range(50) for a in CORRIDOR_ANCHORS for e in uncorrected.feed(Exchange(
        0.1 * k + 0.025 * a, a, c.scale * math.dist((0.0, 0.0), CORRIDOR_ANCHORS[a][:2]) + c.bias[a]))]
    assert math.hypot(out_a[-1].x, out_a[-1].y) < 0.5 * math.hypot(out_c[-1].x, out_c[-1].y)

