"""Hosts following some of a lab's vehicles: one host for vehicles that share the air, one
per vehicle for vehicles with networks of their own; each tracks its vehicles' truth."""
from __future__ import annotations

import dataclasses

import pytest

from navtwin.emulator.fleet import convoy
from navtwin.emulator.scenario import load_scenario
from navtwin.host import config as host_config
from navtwin.host.output import estimate_line
from navtwin.lab import evaluate
from navtwin.lab.fleet import FleetError, followers
from navtwin.lab.run import run_in_memory, truth

OFFICE = load_scenario("office")
CONFIG = host_config.load("office")


def test_vehicles_on_one_air_have_one_host_and_their_own_networks_one_each():
    (one,) = followers(convoy(OFFICE, 3), CONFIG, (3, 1))
    assert one.vehicles == (3, 1) and one.inputs == {"xbee": "xbee", "nanoloc": "nanoloc"}
    assert [v.tag for v in one.config.vehicles] == [18, 16]
    assert [v.router for v in one.config.vehicles] == ["0013A20040A1B2D6", "0013A20040A1B2D4"]
    each = followers(convoy(OFFICE, 3, network="per-vehicle"), CONFIG)
    assert [f.inputs for f in each] == [{"xbee": "xbee", "nanoloc": "nanoloc"},
                                        {"xbee": "xbee2", "nanoloc": "nanoloc2"},
                                        {"xbee": "xbee3", "nanoloc": "nanoloc3"}]
    assert followers(OFFICE, CONFIG)[0].config is CONFIG  # one vehicle: the config as it is


def test_a_vehicle_on_another_line_starts_where_its_line_does():
    sc = convoy(OFFICE, 2)
    turned = dataclasses.replace(sc.fleet[1].trajectory,  # the other way round, 1 m over and up
                                 waypoints=((6.0, 2.0), (2.0, 2.0), (2.0, 5.0), (9.0, 5.0), (9.0, 2.0)))
    sc = dataclasses.replace(sc, vehicles=(dataclasses.replace(sc.fleet[1], trajectory=turned),))
    v1, v2 = followers(sc, CONFIG)[0].config.vehicles
    (x0, y0), (x1, y1) = OFFICE.trajectory.waypoints[0], turned.waypoints[0]
    assert v2.start == pytest.approx((v1.start[0] + x1 - x0, v1.start[1] + y1 - y0))
    assert (v2.heading_deg - v1.heading_deg) % 360 == pytest.approx(180.0)  # -x, not +x


@pytest.mark.parametrize("kw, message", [
    ({"vehicles": (4,)}, "not a list of distinct vehicles of 1..3"),
    ({"vehicles": (2, 2)}, "not a list of distinct vehicles"),
])
def test_bad_follows_are_one_line(kw, message):
    with pytest.raises(FleetError, match=message):
        followers(convoy(OFFICE, 3), CONFIG, **kw)


def test_a_lab_sharing_one_network_and_not_the_other_is_refused():
    sc = convoy(OFFICE, 2, network="per-vehicle")
    sc = dataclasses.replace(sc, ranging=dataclasses.replace(sc.ranging, network="shared"))
    with pytest.raises(FleetError, match="give \\[xbee\\] and \\[ranging\\] the same network"):
        followers(sc, CONFIG)


@pytest.mark.parametrize("network", ["shared", "per-vehicle"])
def test_hosts_following_two_of_three_vehicles_track_each_ones_truth(network):
    """Vehicles 2 and 3 of a convoy of three, followed in memory: each estimate is that
    vehicle's (its error against its own truth is the one-vehicle lab's, not the distance
    between cars), and the gateway's reports of the unfollowed tag are skipped, not lost."""
    sc = convoy(OFFICE, 3, network=network)
    for f in followers(sc, CONFIG, (2, 3)):
        est, pipe = run_in_memory(sc, 2, follower=f, filters=("kf",), duration=30)
        lines = [estimate_line(e) for e in est]
        for k, v in enumerate(f.vehicles, 1):
            mine = evaluate.position_errors(truth(sc, 2, v), evaluate.load_estimates(lines, vehicle=k))
            other = evaluate.position_errors(truth(sc, 2, 1), evaluate.load_estimates(lines, vehicle=k))
            assert mine["kf"]["mean"] < 0.5 < other["kf"]["mean"], (v, mine["kf"], other["kf"])
        assert pipe.counts["reports_lost"] == 0
        assert (pipe.counts["reports_other_tag"] > 0) == (network == "shared")
        assert (pipe.counts["imu_other_router"] > 0) == (network == "shared")


def test_without_a_follower_the_in_memory_host_follows_car_1():
    """A sweep of a scenario with several cars scores car 1: the in-memory host's config is
    given car 1's tag and router, and skips the others' frames."""
    est, pipe = run_in_memory("office-convoy", 3, filters=("kf",), duration=20)
    lines = [estimate_line(e) for e in est]
    mine = evaluate.position_errors(truth("office-convoy", 3, 1), evaluate.load_estimates(lines))
    assert mine["kf"]["mean"] < 0.5 and pipe.counts["reports_other_tag"] > 0
    assert [v.tag for v in pipe.config.vehicles] == [16]
