"""[[anchor_grids]] in a scenario and in the host config: expanded to the same anchors as
[[anchors]] (common.anchorgrid), ids unique across both, a scenario of grids only, and the
scenario written back with its grids as grids."""
import tomllib

import pytest

from navtwin.emulator.scenario import ScenarioError, load_scenario, parse_scenario
from navtwin.host import config as host_config

GRID = {"first_id": 101, "origin": [0.5, 0.5], "spacing_m": 1.0, "count": [2, 2]}


def _office(**over) -> dict:
    doc = tomllib.loads(load_scenario("office").to_toml())
    doc["ranging"]["cycle_ms"] = 250.0  # a slot for each of the 8 anchors
    doc.update(over)
    return doc


def test_a_scenario_of_grids_only_expands_them_and_writes_them_back_as_grids():
    doc = _office(anchor_grids=[GRID])
    del doc["anchors"]
    sc = parse_scenario(doc)
    assert [(a.id, a.x, a.y) for a in sc.all_anchors] == [(101, 0.5, 0.5), (102, 1.5, 0.5),
                                                          (103, 0.5, 1.5), (104, 1.5, 1.5)]
    text = sc.to_toml()
    assert text.count("[[anchor_grids]]") == 1 and "[[anchors]]" not in text
    assert parse_scenario(tomllib.loads(text)) == sc


def test_grids_beside_anchors_and_a_scenario_without_grids_writes_none():
    sc = parse_scenario(_office(anchor_grids=[GRID]))
    assert sorted(sc.anchor_ids) == [1, 2, 3, 4, 101, 102, 103, 104]
    assert "anchor_grids" not in load_scenario("office").to_toml()


@pytest.mark.parametrize("grid, message", [
    ({**GRID, "first_id": 3}, "[[anchor_grids]] #1 first_id reuses anchor id 3 of [[anchors]]"),
    ({**GRID, "first_id": 15}, "[tag] id 16 is also an anchor id"),
    ({**GRID, "spacing_m": 50.0}, "[[anchor_grids]] #1 count the grid spans"),
])
def test_bad_grids_are_one_line_errors(grid, message):
    with pytest.raises(ScenarioError, match="^scenario: " + message.replace("[", r"\[").replace("]", r"\]")) as e:
        parse_scenario(_office(anchor_grids=[grid]))
    assert "\n" not in str(e.value) and "; " in str(e.value)


def test_two_grids_sharing_ids_are_named():
    with pytest.raises(ScenarioError, match=r"\[\[anchor_grids\]\] #2 first_id.*reuses anchor id 102"):
        parse_scenario(_office(anchor_grids=[GRID, {**GRID, "first_id": 102, "origin": [5.0, 5.0]}]))


def test_the_host_config_expands_the_same_grids():
    doc = tomllib.load(open(host_config.CONFIG_DIR / "office.toml", "rb"))
    doc["anchor_grids"] = [{**GRID, "first_id": 1001}, {**GRID, "first_id": 2001, "origin": [5.0, 5.0]}]
    cfg = host_config._parse(doc, "office", "office")
    assert len(cfg.anchors) == 4 + 8 and cfg.anchors[1004] == (1.5, 1.5, 0.0)
    assert host_config.from_dict(cfg.to_dict()) == cfg
    doc["anchor_grids"][1]["first_id"] = 3
    with pytest.raises(host_config.ConfigError, match=r"\[\[anchor_grids\]\] #2 first_id reuses anchor id 3"):
        host_config._parse(doc, "office", "office")
