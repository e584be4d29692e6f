"""The emulated magnetometer: the IGRF-13 field against an independent implementation, the
frames it adds to the SINS stream (and nothing else), its scenario keys."""
import dataclasses
import tomllib

import pytest

from navtwin.common import geomagnetic
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import SCENARIO_DIR, Magnetometer, ScenarioError, load_scenario, parse_scenario
from navtwin.protocols import sins
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import sins_decoder

from ..helpers import navtwin, one_line_error

# (latitude, longitude, decimal year) -> (north, east, down) nT from ppigrf 2.1.0
# (ppigrf.igrf(lon, lat, 0, date, coeff_fn=IGRF13.shc)), an independent implementation of
# the same published IGRF-13 table
PPIGRF = {(34.316, 108.9, 2020.0): (31610.8675, -2153.8146, 42143.5151),  # the lab
          (32.0, 118.0, 2020.0): (32836.9798, -3286.6929, 37739.5370),  # 003's start
          (-60.0, -30.0, 2022.0): (16257.3839, -1576.9916, -25607.2005)}  # secular variation


@pytest.mark.parametrize("where", list(PPIGRF))
def test_igrf13_against_ppigrf(where):
    lat, lon, year = where
    got = geomagnetic.field_ned(lat, lon, 0.0, year)
    assert [g * 1e3 for g in got] == pytest.approx(PPIGRF[where], abs=0.05)  # nT


def test_declination_and_inclination_at_the_lab():
    assert geomagnetic.declination_deg(34.316, 108.9) == pytest.approx(-3.898, abs=1e-3)
    assert geomagnetic.inclination_deg(34.316, 108.9) == pytest.approx(53.064, abs=1e-3)


def _run(tmp_path, name, sc):
    with Emulation(sc, 5, speed=None, ports=False, duration_s=3.0, record=tmp_path / name) as emu:
        emu.run()
    return Recording(tmp_path / name)


def test_it_adds_its_frames_and_changes_nothing_else(tmp_path):
    office = load_scenario("office")
    plain = _run(tmp_path, "plain", office)
    mag = _run(tmp_path, "mag", dataclasses.replace(office, magnetometer=Magnetometer(
        enabled=True, rate_hz=20.0, hard_iron_ut=(3.0, -2.0, 1.0))))
    frames = sins_decoder().decode(mag.read_bytes("sins"))
    samples = b"".join(f.raw for f in frames if f.type == sins.TYPE_SAMPLE)
    mags = [f for f in frames if f.type == sins.TYPE_MAGNETOMETER]
    assert samples == plain.read_bytes("sins")  # the IMU's draws are its own
    assert mag.read_bytes("nanoloc") == plain.read_bytes("nanoloc")
    assert [f.fields["seq"] for f in mags] == list(range(0, 300, 5))  # 20 Hz: every 5th
    for f in mags:  # each right after the sample of its seq
        before = frames[frames.index(f) - 1]
        assert before.type == sins.TYPE_SAMPLE and before.fields["seq"] == f.fields["seq"]
    disabled = dataclasses.replace(office, magnetometer=Magnetometer(enabled=False))
    assert _run(tmp_path, "off", disabled).read_bytes("xbee") == plain.read_bytes("xbee")


def _office(**magnetometer) -> dict:
    data = tomllib.loads((SCENARIO_DIR / "office.toml").read_text())
    return data | {"magnetometer": magnetometer}


@pytest.mark.parametrize("keys, message", [
    ({"enabled": True, "rate_hz": 3.0}, "[magnetometer] rate_hz 3 does not divide the board's "
                                        "100 frames/s; use a rate that does, e.g. 10"),
    ({"soft_iron": [[1, 0, 0], [0, 1, 0]]}, "[magnetometer] soft_iron must be a list of 3 rows of 3 "
                                           "numbers"),
    ({"soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}, "a determinant above 0.1"),
    ({"hard_iron_ut": [500, 0, 0]}, "[magnetometer] hard_iron_ut elements must be in [-200, 200]"),
    ({"year": 2030}, "[magnetometer] year must be in [2020, 2025] (got 2030)"),
    ({"noise_ut": -1}, "[magnetometer] noise_ut must be in [0, 100]"),
    ({"enable": True}, "[magnetometer] has an unknown key 'enable'; did you mean 'enabled'?"),
])
def test_bad_keys_are_one_line(keys, message):
    with pytest.raises(ScenarioError) as e:
        parse_scenario(_office(**keys), "x.toml")
    text = str(e.value)
    assert message in text and "\n" not in text and text.startswith("x.toml: ")


def test_written_back_only_when_given():
    office = load_scenario("office")
    assert "magnetometer" not in office.to_toml()
    sc = parse_scenario(_office(enabled=True, soft_iron=[[1.02, 0.01, 0], [0.01, 0.98, 0],
                                                         [0, 0, 1]]))
    assert "[magnetometer]" in sc.to_toml()
    assert parse_scenario(tomllib.loads(sc.to_toml())) == sc


def test_a_bad_key_stops_navtwin_emulate_with_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('base = "office"\n[magnetometer]\nenabled = true\nsoft_iron = [[1.0, 0.0, 0.0]]\n')
    one_line_error(navtwin("emulate", "--scenario", bad, "--link-dir", tmp_path / "l"),
                   "bad.toml: [magnetometer] soft_iron must be a list of 3 rows of 3 numbers")


def test_the_field_is_the_sites():
    """The magnetometer takes its position from [site] (latitude, longitude, height): at 003's
    start the navigation-frame field is ppigrf's there (x east, y north, z up); a
    [magnetometer] longitude_deg is refused (the key moved to [site])."""
    from navtwin.emulator.magnetometer import earth_field_nav
    sc = load_scenario("rssi-centroid")
    assert (sc.site.latitude_deg, sc.site.longitude_deg, sc.site.height_m) == (32.0, 118.0, 0.0)
    north, east, down = PPIGRF[(32.0, 118.0, 2020.0)]
    field = earth_field_nav(sc.site, sc.area, sc.magnetometer)
    assert [f * 1e3 for f in field] == pytest.approx([east, north, -down], abs=0.05)
    with pytest.raises(ScenarioError, match=r"\[magnetometer\] has an unknown key 'longitude_deg'"):
        parse_scenario(_office(enabled=True, longitude_deg=118.0), "x.toml")
