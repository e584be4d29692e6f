"""The estimate lines' opt-in geodetic position ([output] geodetic): where it goes in the line,
and that it is the estimate's x, y through the area's frame (back to x, y through LocalFrame)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from navtwin.common.earth import WGS84_A
from navtwin.common.geodesy import LocalFrame
from navtwin.host import config as host_config
from navtwin.host.config import ConfigError
from navtwin.host.output import GEODETIC_KEYS, KEYS, estimate_line
from navtwin.host.tracks.base import Estimate

#: The floor of any round trip: both ways go through ECEF coordinates of the earth's size,
#: whose double spacing is 0.93e-9 m, and a longitude near 118 deg is itself resolved to
#: 1.4e-14 deg, 1.3e-9 m east at 32 N; 1e-9 m is finer than the numbers hold (measured: up to
#: 2.9e-9 m over 2.5 km), so the bound is a few ECEF spacings.
ROUND_TRIP_M = 4 * float(np.spacing(WGS84_A))

ANCHORS = "".join(f"[[anchors]]\nid = {i}\nx = {x}\ny = {y}\n"
                  for i, (x, y) in enumerate([(0, 0), (1900, 0), (0, 2200)], 1))


def _config(tmp_path, output: str = "[output]\ngeodetic = true\n", azimuth: float = 37.0):
    p = tmp_path / "geo.toml"
    p.write_text("[site]\nlatitude_deg = 32.0\nlongitude_deg = 118.0\nheight_m = 12.5\n" + ANCHORS +
                 f"[filters]\nx_azimuth_deg = {azimuth}\n" + output)
    return host_config.load(str(p))


def _estimate(x: float, y: float) -> Estimate:
    return Estimate(t=1.5, filter="wcl", x=x, y=y, vx=0.5, vy=-0.25, yaw=0.1,
                    cov=np.eye(4) * 0.04, extrapolated=False)


def test_the_config_asks_for_the_geodetic_position_and_names_its_frame(tmp_path):
    cfg = _config(tmp_path)
    assert cfg.output_frame == LocalFrame(32.0, 118.0, 12.5, 37.0)
    assert host_config.from_dict(cfg.to_dict()) == cfg  # a host recording's config keeps it
    assert _config(tmp_path, output="").output_frame is None  # off unless asked
    assert host_config.load("office").output_frame is None


def test_a_geodetic_line_is_the_plain_line_with_lat_lon_h_after_y(tmp_path):
    frame = _config(tmp_path).output_frame
    e = _estimate(812.25, 1433.5)
    plain, geo = json.loads(estimate_line(e)), json.loads(estimate_line(e, frame))
    assert tuple(plain) == KEYS
    assert tuple(geo) == KEYS[:5] + GEODETIC_KEYS + KEYS[5:]
    assert {k: geo[k] for k in KEYS} == plain
    assert estimate_line(e, None) == estimate_line(e)


@pytest.mark.parametrize("azimuth", [0.0, 37.0, 90.0, 300.0])
def test_lat_lon_h_go_back_to_the_estimates_x_y_through_the_local_frame(tmp_path, azimuth):
    """Over 003's area and beyond: LocalFrame.local(lat, lon, h) of each line is its x, y
    and the floor, to the floating-point floor of ECEF coordinates (ROUND_TRIP_M)."""
    frame = _config(tmp_path, azimuth=azimuth).output_frame
    for x, y in np.random.default_rng(5).uniform(-2500, 2500, (200, 2)):
        line = json.loads(estimate_line(_estimate(float(x), float(y)), frame))
        back = frame.local(line["lat"], line["lon"], line["h"])
        assert np.abs(back - [line["x"], line["y"], 0.0]).max() <= ROUND_TRIP_M


def test_an_output_setting_of_the_wrong_kind_gets_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"\[output\] geodetic must be") as e:
        _config(tmp_path, output="[output]\ngeodetic = 1\n")
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match=r"\[output\] has an unknown key 'latlon'"):
        _config(tmp_path, output="[output]\nlatlon = true\n")
