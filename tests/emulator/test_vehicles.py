"""Vehicles as a list: the top-level tables are vehicle 1, a [[vehicles]] table says the
same, and the world and the emulation hold their vehicles in a list."""
from __future__ import annotations

import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import ScenarioError, Vehicle, load_scenario
from navtwin.emulator.world import World

from .world_helpers import variant

VEHICLE = """
[[vehicles]]
[vehicles.tag]
z = 0.35
[vehicles.board]
period_ms = 20.0
[vehicles.router]
RO = 4
[vehicles.trajectory]
waypoints = [[5.0, 1.0], [8.0, 1.0], [8.0, 5.0], [2.0, 5.0], [2.0, 1.0]]
speed_m_s = 0.3
"""


def test_the_top_level_tables_are_vehicle_1():
    sc = load_scenario("office")
    (v,) = sc.vehicles
    assert v == Vehicle(sc.trajectory, sc.tag, sc.imu, sc.board, sc.xbee.router)
    assert sc.routers_for(7) == (sc.radios_for(7)["router"],)


def test_a_vehicles_table_is_the_same_scenario_as_its_top_level_tables(tmp_path):
    by_vehicle = variant(tmp_path, "office", VEHICLE, "v")
    top = variant(tmp_path, "office", VEHICLE.replace("[[vehicles]]\n", "").replace("vehicles.", "")
                  .replace("[router]", "[xbee.router]"), "v")
    assert by_vehicle == top and by_vehicle.to_toml() == top.to_toml()
    assert by_vehicle.board.period_ms == 20.0 and by_vehicle.xbee.router.RO == 4
    assert by_vehicle.trajectory.speed_m_s == 0.3 and by_vehicle.tag.z == 0.35


@pytest.mark.parametrize("toml, message", [
    (VEHICLE + VEHICLE, "lists 2 vehicles; this version runs 1"),
    ("[tag]\nz = 0.2\n" + VEHICLE, r"\[tag\] is set at the top level and in \[\[vehicles\]\] #1"),
    ("[[vehicles]]\nspeed = 1\n", "#1 has an unknown key 'speed'"),
    ("vehicles = 3\n", "vehicles must be an array of tables"),
])
def test_bad_vehicles_are_one_line_with_the_fix(tmp_path, toml, message):
    with pytest.raises(ScenarioError, match=message) as e:
        variant(tmp_path, "office", toml)
    assert "\n" not in str(e.value)


def test_the_world_and_the_emulation_hold_a_list_of_vehicles(tmp_path):
    sc = variant(tmp_path, "office", VEHICLE, "v")
    w = World(sc, 4)
    (v,) = w.vehicles
    assert v.number == 1 and v.spec == sc.vehicles[0] and v.src16 == sc.routers_for(4)[0]["MY"]
    with Emulation(sc, 4, speed=None, ports=False, duration_s=0.1) as emu:
        assert [r.registers.values["MY"] for r in emu.coordinator.remotes] == [v.src16]
