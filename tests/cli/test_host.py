"""`navtwin host` / `navtwin replay` arguments and host config files: one-line errors."""
import dataclasses
import json
import os

import pytest

from navtwin.host import config as host_config
from navtwin.host import tracks
from navtwin.host.config import ConfigError
from navtwin.host.tracks import DEFAULT

from ..helpers import cli_error, run_cli


@pytest.fixture
def pty_path():
    master, slave = os.openpty()
    yield os.ttyname(slave)
    os.close(slave)
    os.close(master)


def test_host_without_ports(capsys):
    assert "give --xbee PORT" in cli_error(capsys, "host")


def test_host_port_that_does_not_exist(capsys, tmp_path):
    line = cli_error(capsys, "host", "--sins", str(tmp_path / "ttyNOPE"))
    assert line.startswith("navtwin host: error: --sins ") and "cannot open" in line \
        and "check the device path" in line


def test_host_bad_url_scheme(capsys):
    line = cli_error(capsys, "host", "--xbee", "nosuch://x")
    assert line.startswith("navtwin host: error: --xbee ") and "cannot open" in line


def test_host_unknown_filter(capsys, pty_path):
    line = cli_error(capsys, "host", "--sins", pty_path, "--filters", "kf,pf")
    assert "unknown filter 'pf'" in line
    # every track the registry knows, a user's installed ones too, the built-in ones first
    listed = line.split("a comma list of ")[1].split(" or all")[0].split(", ")
    assert listed == list(tracks.names())
    assert listed[:8] == ["sins", "wsn", "kf", "ekf", "ukf", "lc", "tc", "fatci"]


def test_host_unknown_config_name(capsys, pty_path):
    line = cli_error(capsys, "host", "--sins", pty_path, "--config", "garage")
    assert "no host config named 'garage'" in line and "office" in line


def test_host_record_into_a_used_directory(capsys, pty_path, tmp_path):
    (tmp_path / "x").write_text("keep me")
    line = cli_error(capsys, "host", "--sins", pty_path, "--record", str(tmp_path))
    assert "not an empty directory" in line
    assert (tmp_path / "x").read_text() == "keep me"


def test_host_negative_duration(capsys, pty_path):
    assert "--duration" in cli_error(capsys, "host", "--sins", pty_path, "--duration", "-1")


def test_replay_of_a_directory_that_is_no_recording(capsys, tmp_path):
    assert "recording.json" in cli_error(capsys, "replay", str(tmp_path))


def test_help_texts_name_the_commands(capsys):
    code, out, _ = run_cli(capsys, "host", "--help")
    assert code == 0 and "--nanoloc" in out and "--record" in out and "SIGTERM" in out
    code, out, _ = run_cli(capsys, "replay", "--help")
    assert code == 0 and "gives exactly the live run's lines" in " ".join(out.split())


# -- config files -------------------------------------------------------------------------

def test_office_config_is_the_survey_of_scenarios_md():
    cfg = host_config.load("office")
    # shared/specs/scenarios.md, office: anchors, start, latitude, gravity
    assert {i: a[:2] for i, a in cfg.anchors.items()} == {
        1: (1.3, 1.6), 2: (10.8, 1.6), 3: (10.8, 5.4), 4: (1.3, 5.4)}
    assert cfg.vehicles[0].start == (6.0, 1.8) and cfg.vehicles[0].heading_deg == 0.0
    assert cfg.latitude_deg == 34.316 and cfg.local_gravity == 9.7952
    assert cfg.filters == DEFAULT


def test_corridor_config_starts_at_the_origin():
    cfg = host_config.load("corridor")
    assert cfg.vehicles[0].start == (0.0, 0.0) and len(cfg.anchors) == 4


def test_config_round_trips_through_its_dict():
    cfg = host_config.load("office")
    assert host_config.from_dict(cfg.to_dict()) == cfg
    d = cfg.to_dict()
    with_extras = host_config.from_dict({**d, "vehicle": {**d["vehicle"], "tag": 16,
                                                          "router": "0013A20040A1B2D4"},
                                         "filters": {"alignment_s": 3.0, "ukf": {"alpha": 0.5}}})
    assert host_config.from_dict(with_extras.to_dict()) == with_extras


def test_filters_tracks_gives_its_keys_to_every_track_that_declares_them():
    """[filters.tracks]: each track that has the key takes it, a track's own section wins, the
    tracks without it are untouched; the rssi-centroid config's three tracks share their IMU's."""
    d = host_config.load("office").to_dict()
    cfg = host_config.from_dict({**d, "filters": {"tracks": {"gyro_drift_deg_h": 0.5, "alpha": 0.5},
                                                  "wcl": {"gyro_drift_deg_h": 0.7}}})
    assert cfg.settings["geosins"].gyro_drift_deg_h == cfg.settings["centroid"].gyro_drift_deg_h == 0.5
    assert cfg.settings["wcl"].gyro_drift_deg_h == 0.7 and cfg.settings["ukf"].alpha == 0.5
    assert "sins" not in cfg.settings and "kf" not in cfg.settings
    assert host_config.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(host_config.ConfigError, match=r"\[filters.tracks\] nonsense is a setting of no track"):
        host_config.from_dict({**d, "filters": {"tracks": {"nonsense": 1}}})
    shipped = host_config.load("rssi-centroid")
    for key in ("gyro_drift_deg_h", "accel_bias_ug", "start_from"):
        assert len({getattr(shipped.settings[t], key) for t in ("geosins", "centroid", "wcl")}) == 1


def test_estimator_config_carries_the_host_config():
    cfg = host_config.load("office")
    ec = cfg.estimator_config(("wsn", "ukf"))
    assert ec.filters == ("wsn", "ukf") and dict(ec.anchors) == cfg.anchors
    assert ec.start == cfg.vehicles[0].start and ec.local_gravity == cfg.local_gravity
    assert ec.heading_deg == cfg.vehicles[0].heading_deg


def write(tmp_path, text: str) -> str:
    p = tmp_path / "lab.toml"
    p.write_text(text)
    return str(p)


ANCHORS = "".join(f"[[anchors]]\nid = {i}\nx = {x}\ny = {y}\n"
                  for i, (x, y) in enumerate([(0, 0), (5, 0), (5, 5)], 1))


@pytest.mark.parametrize("text, words", [
    ("[site\n", "not valid TOML"),
    ("[garage]\n" + ANCHORS, "unknown section [garage]"),
    ("[site]\nlatitude = 3\n" + ANCHORS, "[site] has an unknown key 'latitude'"),
    ("[site]\nlatitude_deg = 123\n" + ANCHORS, "latitude_deg must be in [-90, 90] (got 123"),
    ("[site]\n", "[[anchors]] missing"),
    (ANCHORS + "[[anchors]]\nid = 1\nx = 0\ny = 1\n", "anchor id 1 appears twice"),
    ("[[anchors]]\nid = 1\nx = 0\n", "anchor 1 y is missing"),
    (ANCHORS + "[vehicle]\nstart = [1]\n", "start must be a list of 2 numbers"),
    (ANCHORS + "[vehicle]\ngyro_range_dps = 100\n", "one of 300, 150, 75"),
    (ANCHORS + "[vehicle]\nrouter = 'xyz'\n", "16 hex digits"),
    (ANCHORS + "[filters]\nenabled = ['kf', 'pf']\n", "unknown filter 'pf'"),
    (ANCHORS + "[filters]\nsmoothing = 3\n", "[filters] has an unknown key 'smoothing'"),
    (ANCHORS + "[filters]\nalignment_s = 'long'\n", "alignment_s must be a number"),
])
def test_bad_config_files_get_one_line_naming_key_and_fix(tmp_path, capsys, pty_path, text, words):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as e:
        host_config.load(path)
    assert words in str(e.value) and path in str(e.value) and "\n" not in str(e.value)
    assert words in cli_error(capsys, "host", "--sins", pty_path, "--config", path)


def test_a_good_config_file_is_read(tmp_path):
    cfg = host_config.load(write(tmp_path, ANCHORS + "[vehicle]\nstart = [1, 2]\ntag = 16\n"
                                 "[filters]\nenabled = ['ukf']\nalignment_s = 2.5\n"))
    assert cfg.vehicles[0].start == (1.0, 2.0) and cfg.vehicles[0].tag == 16 and cfg.filters == ("ukf",)
    assert cfg.estimator_config().alignment_s == 2.5 and cfg.anchors[3] == (5.0, 5.0, 0.0)


def test_configs_recorded_in_the_first_layout_still_load(root):
    """Host recordings made before the config had sections hold a flat config
    (fixtures/host-config-v1: written by navtwin 0.1's HostConfig.to_dict)."""
    v1 = json.loads((root / "fixtures" / "host-config-v1" / "configs.json").read_text())
    for name in ("office", "corridor"):  # later: the corridor's calibration, fatci's sets from it
        shipped = host_config.load(name)
        shipped = dataclasses.replace(shipped, calibration=None, settings={
            k: v for k, v in shipped.settings.items() if k != "fatci"})
        assert host_config.from_dict(v1[name]).to_dict() == shipped.to_dict()
    tuned = host_config.from_dict(v1["tuned"])
    assert (tuned.settings["ukf"].alpha, tuned.settings["ukf"].kappa) == (0.5, 0.0)
    assert tuned.settings["sins"].vrw_m_s_rt_hr == 3.0
    assert tuned.range_bias_m == {1: 0.3} and tuned.vehicles[0].tag == 16
    assert tuned.settings["ekf"].tight == tuned.settings["ukf"].tight == "toa"


def test_a_tight_shared_in_filters_still_means_both_tight_tracks(tmp_path):
    """Configs and host recordings written before issue 18 have ``tight`` in [filters], for
    the EKF and the UKF at once; it reads as each one's own, which a section's ``tight`` beats."""
    shared = host_config.load(write(tmp_path, ANCHORS + '[filters]\ntight = "toa"\n'
                                    '[filters.ukf]\nalpha = 0.5\n'))
    own = host_config.load(write(tmp_path, ANCHORS + '[filters.ekf]\ntight = "toa"\n'
                                 '[filters.ukf]\ntight = "toa"\nalpha = 0.5\n'))
    assert shared == own and shared.settings["ukf"].alpha == 0.5
    assert host_config.from_dict(shared.to_dict()) == shared
    both = host_config.load(write(tmp_path, ANCHORS + '[filters]\ntight = "toa"\n'
                                  '[filters.ukf]\ntight = "tdoa"\n'))
    assert (both.settings["ekf"].tight, both.settings["ukf"].tight) == ("toa", "tdoa")
    with pytest.raises(ConfigError, match=r"\[filters.ekf\] tight must be one of 'toa', 'tdoa'"):
        host_config.load(write(tmp_path, ANCHORS + '[filters]\ntight = "rss"\n'))


def test_a_config_file_that_is_not_utf8_gets_one_line(tmp_path):
    """Found by the host_config fuzz target (tests/fuzz): a UnicodeDecodeError escaped."""
    path = tmp_path / "lab.toml"
    path.write_bytes(b"[[anchors]]\nid = 1" + b"\xcd" * 106 + b"\nx = 0\ny = 0\n")
    with pytest.raises(ConfigError) as e:
        host_config.load(str(path))
    assert "not UTF-8 text" in str(e.value) and str(path) in str(e.value)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("text, problem", [
    (b"[timing]\nhold_s = " + b"{a = " * 2000, "arrays or tables nested too deeply"),
    (b"[[anchors]]\nid = " + b"1" * 4400, "an integer of more than 4300 digits"),
])
def test_a_config_file_past_tomllibs_limits_gets_one_line(tmp_path, text, problem):
    """The host_config fuzz target's seeds: RecursionError and ValueError escaped load()."""
    path = tmp_path / "lab.toml"
    path.write_bytes(text)
    with pytest.raises(ConfigError) as e:
        host_config.load(str(path))
    assert str(e.value) == f"{path}: {problem}; shorten it"


def test_an_integer_past_the_float_range_gets_one_line(tmp_path):
    """As the scenario fuzz target found for scenarios: OverflowError from math.isfinite."""
    path = tmp_path / "lab.toml"
    path.write_text(ANCHORS + "[site]\nlatitude_deg = 1" + "0" * 400 + "\n")
    with pytest.raises(ConfigError) as e:
        host_config.load(str(path))
    assert "latitude_deg must be a finite number" in str(e.value) and "\n" not in str(e.value)
