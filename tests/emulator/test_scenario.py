"""Scenario files: shipped contents, validation errors (one line, key named, fix given),
round trip through to_toml, and the documentation table."""
import math
import tomllib

import pytest

from navtwin.emulator.scenario import (SCENARIO_NAMES, ScenarioError, load_scenario, parse_scenario,
                               schema_markdown)

from ..helpers import GRAVITY, LATITUDE_DEG, OFFICE_ANCHORS, OFFICE_START, ROOT
from .world_helpers import variant


def test_shipped_names():
    assert set(SCENARIO_NAMES) >= {"office", "corridor", "corridor-outage"}


def test_office_is_papers_lab():
    """000 sect. 3.3: anchors, start, latitude, gravity as the host's office config has them
    (which tests/cli/test_host.py checks against shared/specs/scenarios.md)."""
    sc = load_scenario("office")
    assert [(a.x, a.y) for a in sc.anchors] == [(x, y) for x, y, _ in OFFICE_ANCHORS.values()]
    assert sc.trajectory.waypoints[0] == OFFICE_START
    (x0, y0), (x1, y1) = sc.trajectory.waypoints[:2]
    assert math.atan2(y1 - y0, x1 - x0) == 0.0  # heading 0
    assert sc.site.latitude_deg == LATITUDE_DEG and sc.site.local_gravity == GRAVITY
    assert sc.area.size == (12.0, 7.0)
    assert sc.trajectory.alignment_s > 0 and 0.3 <= sc.trajectory.speed_m_s <= 0.5


def test_corridor_scenarios_are_001s():
    c, o = load_scenario("corridor"), load_scenario("corridor-outage")
    assert c.duration_s == 127.0 and c.trajectory.loops == 2 and len(c.anchors) == 4
    assert c.trajectory.waypoints[0] == (0.0, 0.0)
    assert c.ranging.cycle_ms == 100.0 and c.board.period_ms == 10.0
    assert o.duration_s == 60.0 and o.anchors == c.anchors
    windows = sorted((f.start_s, f.end_s) for f in o.faults if f.KIND == "anchor_outage" and f.anchor == 2)
    assert windows == [(18.0, 23.0), (40.0, 45.0)]


def test_ports_and_radio_identity_follow_wire_formats():
    """wire-formats.md section 2 table of default identities; the router MY comes from the seed."""
    sc = load_scenario("office")
    assert sc.ports == {"sins": {"baud": 115200}, "xbee": {"baud": 115200, "api_mode": 2},
                        "nanoloc": {"baud": 115200}}
    r = sc.radios
    c, rt = r["coordinator"], r["router"]
    assert (c["SH"], c["SL"], c["MY"], c["NI"], c["HV"], c["VR"], c["AP"], c["BD"]) == \
        (0x0013A200, 0x40A1B2C3, 0, "LAB-COORD", 0x1E46, 0x21A7, 2, 7)
    assert (rt["SH"], rt["SL"], rt["NI"], rt["HV"], rt["VR"], rt["AP"], rt["BD"], rt["NP"], rt["RO"]) == \
        (0x0013A200, 0x40A1B2D4, "SINS-ROUTER", 0x1E46, 0x22A7, 0, 7, 84, 3)
    assert 0 < rt["MY"] < 0xFFF8
    assert sc.radios == sc.radios_for(sc.seed)
    mys = {sc.radios_for(seed)["router"]["MY"] for seed in range(20)}
    assert len(mys) > 15  # the join differs between seeds


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_to_toml_round_trip(name, tmp_path):
    sc = load_scenario(name)
    text = sc.to_toml()
    assert parse_scenario(tomllib.loads(text)) == sc
    path = tmp_path / "as_run.toml"
    path.write_text(text)
    assert load_scenario(path) == sc
    assert "base" not in tomllib.loads(text)  # self-contained


def test_base_overrides_merge(tmp_path):
    sc = variant(tmp_path, "office", "[trajectory]\nspeed_m_s = 0.45\n[imu]\ngyro_arw_deg_rt_h = 1.0\n")
    office = load_scenario("office")
    assert sc.trajectory.speed_m_s == 0.45 and sc.imu.errors.gyro_arw_deg_rt_h == 1.0
    assert sc.trajectory.waypoints == office.trajectory.waypoints  # merged key by key
    assert sc.imu.errors.accel_vrw_m_s_rt_h == office.imu.errors.accel_vrw_m_s_rt_h
    assert sc.name == "variant"


def test_a_geodetic_anchor_is_placed_by_the_local_frame(tmp_path):
    """lat_deg, lon_deg (and height_m) place an anchor where common.geodesy puts that point
    in the area's frame; without height_m it sits at the tag's height, as x, y anchors do."""
    office = load_scenario("office")
    lat, lon, h = (float(v) for v in office.frame.geodetic([2.0, 1.0, 2.5]))
    sc = variant(tmp_path, "office", f"[[anchors]]\nid = 1\nlat_deg = {lat!r}\nlon_deg = {lon!r}\n"
                                     f"[[anchors]]\nid = 2\nlat_deg = {lat!r}\nlon_deg = {lon!r}\n"
                                     f"height_m = {h!r}\n[[anchors]]\nid = 3\nx = 2.0\ny = 1.0\n")
    assert sc.anchor_position(sc.anchors[0]) == pytest.approx((2.0, 1.0, sc.tag.z), abs=1e-6)
    assert sc.anchor_position(sc.anchors[1]) == pytest.approx((2.0, 1.0, 2.5), abs=1e-6)
    assert sc.anchor_position(sc.anchors[2]) == (2.0, 1.0, sc.tag.z)
    assert parse_scenario(tomllib.loads(sc.to_toml())) == sc  # written back as given


def test_a_grade_is_picked_by_name_and_overridden_key_by_key(tmp_path):
    """[imu] grade picks the profile; a key set in [imu] replaces that field only."""
    from navtwin.emulator.imu_errors import GRADES

    sc = variant(tmp_path, "office", '[imu]\ngrade = "paper003"\naccel_bias_ug = 20.0\n')
    assert sc.imu.errors.accel_bias_ug == 20.0
    assert sc.imu.errors.gyro_bias_instability_deg_h == GRADES["paper003"].gyro_bias_instability_deg_h == 0.04
    assert load_scenario("office").imu.errors == GRADES["adis16350"]


def test_the_scenario_as_run_states_every_imu_error_so_it_replays_after_a_grade_changes(
        tmp_path, monkeypatch):
    """to_toml (a recording's scenario.toml) writes each error field's value, not only the
    grade's name: read back after the grade's figures change, it is the IMU that ran."""
    import dataclasses

    from navtwin.emulator import imu_errors

    ran = load_scenario("office")
    text = ran.to_toml()
    written = tomllib.loads(text)["imu"]
    assert {f.name: written[f.name] for f in dataclasses.fields(imu_errors.ImuErrors)} == \
        dataclasses.asdict(imu_errors.GRADES["adis16350"])
    changed = dataclasses.replace(imu_errors.GRADES["adis16350"], gyro_arw_deg_rt_h=2.1)
    monkeypatch.setitem(imu_errors.GRADES, "adis16350", changed)
    (tmp_path / "ran.toml").write_text(text)
    assert load_scenario(str(tmp_path / "ran.toml")).imu.errors == ran.imu.errors != changed


BAD = [
    ("[trajectory]\nspeed_m_s = -1\n", "[trajectory] speed_m_s must be in (0, 100] (got -1 m/s); set a positive speed up to 100 m/s"),
    ("[trajectory]\nsped_m_s = 1\n", "[trajectory] has an unknown key 'sped_m_s'; did you mean 'speed_m_s'?"),
    ("[trajectroy]\nspeed_m_s = 1\n", "unknown key 'trajectroy'; did you mean 'trajectory'?"),
    ('duration_s = "long"\n', "duration_s must be a number"),
    ('[[faults]]\nkind = "blackout"\nstart_s = 1.0\nend_s = 2.0\n', "[[faults]] #1 kind must be one of"),
    ('[[faults]]\nkind = "nlos"\nanchor = 9\nstart_s = 1.0\nend_s = 2.0\n', "[[faults]] #1 anchor 9 is not in"),
    ('[[faults]]\nkind = "link_loss"\nstart_s = 3.0\nend_s = 2.0\n', "[[faults]] #1 end_s must be after start_s"),
    ('[[faults]]\nkind = "anchor_outage"\nstart_s = 3.0\nend_s = 4.0\n', "[[faults]] #1 anchor is missing; add anchor"),
    ('[[faults]]\nkind = "link_loss"\nanchor = 1\nstart_s = 3.0\nend_s = 4.0\n', "unknown key 'anchor'"),
    ("[imu]\ngyro_range_dps = 75\n", "[imu] filter_taps must be >= 16 at gyro_range_dps = 75"),
    ("[imu]\ngyro_range_dps = 200\n", "[imu] gyro_range_dps must be one of 75, 150, 300"),
    ('[imu]\ngrade = "tactical"\n', "[imu] grade must be one of 'adis16350', 'paper003' (got 'tactical'); "
                                    "use one of 'adis16350', 'paper003'"),
    ("[imu]\ngyro_bias_corr_s = -1.0\n", "[imu] gyro_bias_corr_s must be in [0, 1000000] (got -1 s)"),
    ("[trajectory]\nturn_radius_m = 3.0\n", "[trajectory] turn_radius_m 3 m (with transition_m 0.4 m) does not fit"),
    ("[trajectory]\nwaypoints = [[6.0, 1.8], [9.8, 1.8], [10.0, 5.0], [2.0, 2.5]]\n",
     "[trajectory] waypoints of a closed loop must pass straight through the first waypoint"),
    ("[trajectory]\nspeed_m_s = 3.0\n", "[trajectory] speed_m_s 3 m/s cannot be reached and stopped"),
    ("[[anchors]]\nid = 1\nx = 20.0\ny = 1.0\n", "[[anchors]] #1 x (20, 1) m is outside the area"),
    ("[[anchors]]\nid = 1\nx = 2.0\ny = 1.0\n[[anchors]]\nid = 1\nx = 3.0\ny = 1.0\n",
     "[[anchors]] #2 id 1 is used by another anchor"),
    ("[tag]\nid = 1\n", "[tag] id 1 is also an anchor id"),
    ("[[anchors]]\nid = 1\ny = 1.0\n", "[[anchors]] #1 x is missing; give both coordinates"),
    ("[[anchors]]\nid = 1\nlat_deg = 34.316\n", "[[anchors]] #1 lon_deg is missing; give both"),
    ("[[anchors]]\nid = 1\nx = 2.0\nlat_deg = 34.316\n", "[[anchors]] #1 lat_deg and lon_deg go without x and y"),
    ("[[anchors]]\nid = 1\n", "[[anchors]] #1 x and y, or lat_deg and lon_deg, must be given; place"),
    ("[[anchors]]\nid = 1\nx = 2.0\ny = 1.0\nlat_deg = 34.316\nlon_deg = 108.9\n",
     "[[anchors]] #1 lat_deg and lon_deg go without x and y; place the anchor with one pair"),
    ("[[anchors]]\nid = 1\nx = 2.0\ny = 1.0\nheight_m = 3.0\n", "[[anchors]] #1 height_m goes with lat_deg"),
    ("[[anchors]]\nid = 1\nlat_deg = 34.316\nlon_deg = 108.9\nz = 3.0\n", "[[anchors]] #1 z goes with x and y"),
    ("[[anchors]]\nid = 1\nlat_deg = 34.4\nlon_deg = 108.9\n", "[[anchors]] #1 x (0, 9318.02) m is outside the area"),
    ("[site]\nlongitude_deg = 190\n", "[site] longitude_deg must be in [-180, 180] (got 190 deg)"),
    ("[xbee.router]\nNP = 100\n", "[xbee.router] NP must be in [1, 84] (got 100 bytes)"),
    ("[xbee.router]\nBD = 3\n", "[xbee.router] BD 9600 bit/s differs from the board's 115200"),
    ("[ranging]\nslot_ms = 5.0\n", "[ranging] slot_ms 5 ms is too short"),
    ("[area]\nsize = [12.0]\n", "[area] size must be a list of 2 numbers"),
    ('[trajectory]\nwaypoints = [[6.0, 1.8], [9.8, "x"]]\n', "[trajectory] waypoints[1][1] must be a number"),
    ("[site]\nlatitude_deg = 100\n", "[site] latitude_deg must be in [-90, 90] (got 100 deg)"),
    ("[board]\nstart_ms = 0.1\n", "[board] start_ms 0.1 ms is before the first SPI read ends"),
    ("[trajectory\nspeed = 1\n", "not valid TOML (Expected ']'"),
]


@pytest.mark.parametrize("toml, expected", BAD, ids=[e[:30] for _, e in BAD])
def test_bad_file_gets_one_line_naming_the_key_and_fix(tmp_path, toml, expected):
    path = tmp_path / "bad.toml"
    path.write_text('base = "office"\n' + toml)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("bad.toml: ")
    assert expected in msg
    assert "; " in msg  # problem; fix


def test_missing_tables_and_unknown_names(tmp_path):
    path = tmp_path / "bare.toml"
    path.write_text('name = "x"\nduration_s = 3.0\n')
    with pytest.raises(ScenarioError, match=r"^bare.toml: area is missing; add a \[area\] table$"):
        load_scenario(path)
    with pytest.raises(ScenarioError, match="unknown scenario 'nope'; use one of .*office"):
        load_scenario("nope")
    with pytest.raises(ScenarioError, match="no scenario file"):
        load_scenario(tmp_path / "none.toml")
    loop = tmp_path / "loop.toml"
    loop.write_text('base = "loop.toml"\n')
    with pytest.raises(ScenarioError, match="base chain loops back"):
        load_scenario(loop)


def test_docs_carry_the_generated_key_table():
    """docs/scenarios.md documents every key: its table is generated from the declarations."""
    doc = (ROOT / "docs" / "scenarios.md").read_text(encoding="utf-8")
    assert schema_markdown() in doc


@pytest.mark.parametrize("text, problem", [
    (b"duration_s = " + b"[" * 2000, "arrays or tables nested too deeply"),
    (b'base = "office"\nduration_s = ' + b"1" * 4400, "an integer of more than 4300 digits"),
])
def test_a_file_past_tomllibs_limits_is_a_one_line_error(tmp_path, text, problem):
    """The scenario fuzz target's seeds: RecursionError and ValueError escaped the reader."""
    (tmp_path / "deep.toml").write_bytes(text)
    with pytest.raises(ScenarioError) as e:
        load_scenario(tmp_path / "deep.toml")
    assert str(e.value) == f"deep.toml: {problem}; shorten it"


#: Found by the scenario fuzz target (tests/fuzz): a TOML integer past the float range where
#: a number is due raised OverflowError (math.isfinite) instead of a ScenarioError.
FUZZ_HUGE_INT = b'base = "office"\nduration_s = ' + b"1" * 2344 + b"0" * 571 + b"4099276460824344803"


def test_an_integer_past_the_float_range_is_a_one_line_error(tmp_path):
    (tmp_path / "huge.toml").write_bytes(FUZZ_HUGE_INT)
    with pytest.raises(ScenarioError) as e:
        load_scenario(tmp_path / "huge.toml")
    assert str(e.value) == ("huge.toml: duration_s must be a finite number (got an integer of "
                            "2934 digits); write a finite number")


def test_a_base_with_a_newline_is_named_on_one_line(tmp_path):
    """Found by the scenario fuzz target (tests/fuzz): the path was quoted with its newline."""
    (tmp_path / "nl.toml").write_bytes(b'base = "\\nfice"\nduration_s0= 1e400\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(tmp_path / "nl.toml")
    assert str(e.value) == f"no scenario file {tmp_path}/\\nfice; check the path"


def test_a_base_name_too_long_for_the_file_system_is_one_line(tmp_path):
    """Found by the scenario fuzz target (tests/fuzz, 1M inputs): OSError ENAMETOOLONG
    escaped the reader."""
    (tmp_path / "long.toml").write_text(f'base = "{"1" * 600}fuzz.toml"\n')
    with pytest.raises(ScenarioError) as e:
        load_scenario(tmp_path / "long.toml")
    msg = str(e.value)
    assert "\n" not in msg and "File name too long" in msg and len(msg) < 200
