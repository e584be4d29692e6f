"""Fusion tracks are plug-ins: a track from outside the package, registered through the
registry API or an entry point, runs in replay beside the built-in ones, with no edit of the
estimator (host.tracks, docs/filters.md)."""
from __future__ import annotations

import importlib
import json
import re
from pathlib import Path

import pytest

from navtwin.host import config as host_config
from navtwin.host import tracks
from navtwin.host.bench import write_host_recording
from navtwin.host.output import estimate_line
from navtwin.host.replay import replay
from navtwin.protocols.recording import Recording

from ...helpers import OFFICE
from ...packages import write
from ..synthetic import synthetic_chunks


#: A toy track: the latest WSN fix, moved by its one setting along x.
TOY = '''
from dataclasses import dataclass

from navtwin.common.schema import between, key
from navtwin.host.tracks.base import Track, estimate
from navtwin.host.measurements import Fix


@dataclass(frozen=True)
class ToySettings:
    offset_m: float = key(0.0, "m", "added to the fix's x", between(-10, 10))


class Toy(Track):
    name = "{name}"
    Settings = ToySettings

    def __init__(self, ctx, settings=None):
        super().__init__(ctx, settings)
        self.last = None

    def handlers(self):
        return {{Fix: self.fix}}

    def fix(self, fix):
        self.last = fix
        self.updates["fix"] += 1

    def estimate(self, b, yaw):
        f = self.last
        if f is None:
            return None
        return estimate(b, self.name, (f.p[0] + self.settings.offset_m, f.p[1]), (0.0, 0.0), None,
                        [0.0] * 16, self.ctx.stale(b, f.t))
'''


def toy_module(tmp_path: Path, monkeypatch, module: str, name: str):
    (tmp_path / f"{module}.py").write_text(TOY.format(name=name))
    monkeypatch.syspath_prepend(str(tmp_path))
    return importlib.import_module(module)


def lines(rec_path, **overrides) -> dict[str, list[dict]]:
    out: list[str] = []
    replay(Recording(rec_path), lambda es: out.extend(map(estimate_line, es)), **overrides)
    by: dict[str, list[dict]] = {}
    for line in out:
        e = json.loads(line)
        by.setdefault(e["filter"], []).append(e)
    return by


@pytest.fixture
def registered(tmp_path, monkeypatch):
    mod = toy_module(tmp_path, monkeypatch, "navtwin_toy_registered", "toy")
    tracks.register(mod.Toy)
    yield mod.Toy
    tracks.unregister("toy")


def test_a_registered_track_runs_in_replay_with_its_own_config_section(registered, tmp_path):
    assert "toy" in tracks.names() and tracks.get("toy") is registered
    d = OFFICE.to_dict()
    config = host_config.from_dict({**d, "filters": {**d["filters"], "toy": {"offset_m": 1.5}}})
    assert config.settings["toy"].offset_m == 1.5
    filters = host_config.parse_filters("wsn,toy,kf")
    assert filters == ("wsn", "kf", "toy")  # registered tracks follow the built-in ones
    rec = write_host_recording(tmp_path / "rec", config, filters,
                               synthetic_chunks(OFFICE, 6.0, seed=3))
    got = lines(rec)  # the recorded config, with its [filters.toy], read back
    assert got["toy"], "the toy track emitted nothing"
    wsn = {e["t"]: e for e in got["wsn"]}
    for e in got["toy"]:
        if e["t"] in wsn:
            assert e["x"] == pytest.approx(wsn[e["t"]]["x"] + 1.5, abs=1e-12)
            assert e["y"] == wsn[e["t"]]["y"]
    # the toy changes nothing of the built-in tracks
    assert lines(rec, filters=("wsn", "kf")) == {k: v for k, v in got.items() if k != "toy"}


def test_a_bad_setting_of_a_registered_track_is_one_line(registered, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text((host_config.CONFIG_DIR / "office.toml").read_text()
                    + "\n[filters.toy]\noffset_m = 99.0\n")
    with pytest.raises(host_config.ConfigError, match=r"\[filters.toy\] offset_m must be in "
                                                      r"\[-10, 10\]"):
        host_config.load(str(path))


def test_an_entry_point_track_runs_in_replay(tmp_path, monkeypatch):
    toy_module(tmp_path, monkeypatch, "navtwin_toy_ep", "toy_ep")
    write(tmp_path, "navtwin_toy", f"[{tracks.GROUP}]\ntoy_ep = navtwin_toy_ep:Toy\n")
    assert "toy_ep" in tracks.names()
    rec = write_host_recording(tmp_path / "rec", OFFICE, ("kf",),
                               synthetic_chunks(OFFICE, 4.0, seed=5))
    got = lines(rec, filters=host_config.parse_filters("kf,toy_ep"))
    assert set(got) == {"kf", "toy_ep"} and got["toy_ep"]


def test_the_estimator_names_no_track():
    source = (Path(tracks.__file__).parent.parent / "estimator.py").read_text()
    for name in tracks.BUILT_IN:
        assert not re.search(rf"""["']{name}["']""", source), name
