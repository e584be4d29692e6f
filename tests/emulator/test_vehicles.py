"""Vehicles: the top-level tables are vehicle 1, each [[vehicles]] table one more; their
ports, radios, tags and truth, on one air or each on its own."""
from __future__ import annotations

import tomllib

import numpy as np
import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import ScenarioError, Vehicle, load_scenario, parse_scenario
from navtwin.emulator.truth import HEADER, csv_rows
from navtwin.emulator.world import World
from navtwin.protocols.stream import Frame, XBeeDecoder, nanoloc_decoder, sins_decoder

from .world_helpers import port_bytes, variant

SECOND = """
[[vehicles]]
[vehicles.tag]
id = {tag}
[vehicles.router]
SL = {sl}
[vehicles.trajectory]
waypoints = [[5.0, 1.0], [8.0, 1.0], [8.0, 5.0], [2.0, 5.0], [2.0, 1.0]]
speed_m_s = 0.3
"""


def fleet(n: int, extra: str = "") -> str:
    return extra + "".join(SECOND.format(tag=16 + k, sl=0x40A1B2D4 + k) for k in range(1, n))


def test_the_top_level_tables_are_vehicle_1():
    sc = load_scenario("office")
    (v,) = sc.fleet
    assert v == Vehicle(sc.trajectory, sc.tag, sc.imu, sc.board, sc.xbee.router)
    assert sc.routers_for(7) == (sc.radios_for(7)["router"],)
    assert list(sc.ports) == ["sins", "xbee", "nanoloc"]


def test_a_first_vehicles_table_without_top_level_ones_is_vehicle_1():
    office = load_scenario("office")
    data = tomllib.loads(office.to_toml())
    data["vehicles"] = [{"trajectory": data.pop("trajectory"), "tag": data.pop("tag"),
                         "router": data["xbee"].pop("router")}]
    assert parse_scenario(data) == office


def test_further_vehicles_start_from_vehicle_1s_tables_and_round_trip(tmp_path):
    sc = variant(tmp_path, "office", '[imu]\ngrade = "paper003"\n' + fleet(3), "v")
    assert len(sc.fleet) == 3 and [v.tag.id for v in sc.fleet] == [16, 17, 18]
    second = sc.fleet[1]
    assert second.imu == sc.imu and second.board == sc.board  # taken from vehicle 1
    assert second.trajectory.speed_m_s == 0.3 and second.router.SL == 0x40A1B2D5
    assert parse_scenario(tomllib.loads(sc.to_toml())) == sc
    assert list(sc.ports) == ["sins", "xbee", "nanoloc", "sins2", "sins3"]
    per = variant(tmp_path, "office", '[xbee]\nnetwork = "per-vehicle"\n[ranging]\nnetwork = '
                  '"per-vehicle"\n' + fleet(2), "p")
    assert list(per.ports) == ["sins", "xbee", "nanoloc", "sins2", "xbee2", "nanoloc2"]


@pytest.mark.parametrize("toml, message", [
    (SECOND.format(tag=16, sl=0x40A1B2D5), r"vehicle 2 \[tag\] id 16 is vehicle 1's tag too"),
    (SECOND.format(tag=17, sl=0x40A1B2D4), r"SL 0X40A1B2D4 .* is vehicle 1's router too"),
    (SECOND.format(tag=3, sl=0x40A1B2D5), r"id 3 is also an anchor id"),
    (SECOND.format(tag=17, sl=0x40A1B2D5).replace("[8.0, 5.0], [2.0, 5.0]", "[8.0, 50.0], [2.0, 50.0]"),
     r"vehicle 2 \[trajectory\] waypoints 3 \(8, 50\) m is outside the area"),
    (fleet(2) + '[[faults]]\nkind = "byte_drop"\nport = "sins3"\nprobability = 0.1\n',
     r"port sins3: the scenario has vehicles 1 to 2 and its ports are sins, xbee, nanoloc, sins2"),
    (fleet(2) + '[[faults]]\nkind = "coordinator_reset"\nvehicle = 2\n',
     r"vehicle 2: the vehicles share one coordinator"),
    (fleet(2) + '[[faults]]\nkind = "board_reset"\nvehicle = 3\n', "the scenario has vehicles 1 to 2"),
    ("[[vehicles]]\nspeed = 1\n", "#1 has an unknown key 'speed'"),
    ("vehicles = 3\n", "vehicles must be an array of tables"),
    (fleet(257), "the scenario has 257 vehicles; this version runs up to 256"),
])
def test_bad_vehicles_are_one_line_with_the_fix(tmp_path, toml, message):
    with pytest.raises(ScenarioError, match=message) as e:
        variant(tmp_path, "office", toml)
    assert "\n" not in str(e.value)


def _run(sc, seed=4, duration=4.0):
    out = {}
    with Emulation(sc, seed, speed=None, ports=False, duration_s=duration,
                   sink=lambda c: out.setdefault(c.port, []).append(c.data)) as emu:
        summary = emu.run()
    return {p: b"".join(d) for p, d in out.items()}, summary


def _packets(data: bytes) -> list[Frame]:
    return [f for f in XBeeDecoder(True).decode(data) if isinstance(f, Frame) and f.type == 0x90]


def test_a_shared_air_carries_every_vehicle_and_adding_one_changes_no_other(tmp_path):
    """Vehicle 1's board bytes are its bytes alone; the coordinator's port carries both
    routers' packets; the anchors range the tags in turn, so each tag's rate halves."""
    alone, _ = _run(load_scenario("office"))
    two, summary = _run(variant(tmp_path, "office", fleet(2), "two"))
    assert two["sins"] == alone["sins"] and len(two["sins2"]) == len(two["sins"])
    senders = {p.fields["src64"] for p in _packets(two["xbee"])}
    assert senders == {0x0013A20040A1B2D4, 0x0013A20040A1B2D5}
    reports = [f for f in nanoloc_decoder().decode(two["nanoloc"]) if isinstance(f, Frame)]
    tags = np.array([r.fields["tag"] for r in reports])
    alone_reports = [f for f in nanoloc_decoder().decode(alone["nanoloc"]) if isinstance(f, Frame)]
    assert set(tags.tolist()) == {16, 17}
    assert abs(len(reports) - len(alone_reports)) <= 4  # the same exchanges, shared
    assert abs(int((tags == 16).sum()) - int((tags == 17).sum())) <= 4
    assert summary["ports"]["xbee"]["dropped_tx_buffer"] == 0


def test_a_shared_air_drops_what_it_cannot_carry_and_counts_it(tmp_path):
    """A router holds the channel about 0.37 of the time and one coordinator's UART carries
    about 2.4 routers' streams: with four routers both overflow. Every SINS frame is carried,
    dropped by a router's full queue or by the coordinator's full transmit buffer; each
    router's packets stay in order."""
    data, summary = _run(variant(tmp_path, "office", fleet(4), "four"))
    xbee = summary["ports"]["xbee"]
    packets = _packets(data["xbee"])
    sent = sum(summary["ports"][p]["frames"] for p in ("sins", "sins2", "sins3", "sins4"))
    assert xbee["dropped_channel"] > 0 and xbee["dropped_tx_buffer"] > 0
    # the rest: lost on the link, or still in a queue or on the air when the run ended
    assert 0.97 * sent <= len(packets) + xbee["dropped_channel"] + xbee["dropped_tx_buffer"] <= sent
    assert xbee["bytes"] <= 4.0 * 11520 + 200  # the line's 11 520 B/s
    for src in {p.fields["src64"] for p in packets}:
        frames = sins_decoder().decode(b"".join(p.fields["data"] for p in packets if p.fields["src64"] == src))
        seqs = [f.fields["seq"] for f in frames if isinstance(f, Frame)]
        assert len(seqs) > 100 and seqs == sorted(seqs)


def test_the_channel_serves_first_come_and_drops_at_a_full_router_queue():
    from navtwin.emulator.channel import TX_QUEUE, Channel, Offered
    from navtwin.emulator.world import Event

    ch = Channel()
    ev = lambda t: Event(t, "xbee", b"")  # noqa: E731
    # vehicle 2 asks at 0 and holds 10; vehicle 1 at 5 waits 5; a lost packet holds it all the same
    out, air = ch.share([Offered(1, 5, 3, ev(9), []), Offered(2, 0, 10, ev(14), []),
                         Offered(2, 11, 2, None, [])])
    assert [e.t_ns for e in out] == [14, 9 + 5] and ch.free_ns == 15
    # one router offering TX_QUEUE + 2 packets at once: the queue takes TX_QUEUE
    out, _ = ch.share([Offered(3, 100, 10, ev(100 + k), []) for k in range(TX_QUEUE + 2)])
    assert len(out) == TX_QUEUE and ch.dropped == 2


def test_per_vehicle_networks_leave_vehicle_1s_lab_as_it_was_alone(tmp_path):
    alone, _ = _run(load_scenario("office"))
    sc = variant(tmp_path, "office", '[xbee]\nnetwork = "per-vehicle"\n[ranging]\nnetwork = '
                 '"per-vehicle"\n' + fleet(3), "own")
    many, _ = _run(sc)
    for port in ("sins", "xbee", "nanoloc"):
        assert many[port] == alone[port], port
    assert {p.fields["src64"] for p in _packets(many["xbee3"])} == {0x0013A20040A1B2D6}
    tags = {f.fields["tag"] for f in nanoloc_decoder().decode(many["nanoloc2"]) if isinstance(f, Frame)}
    assert tags == {17}
    assert many["nanoloc2"] != many["nanoloc"]  # its own draws


def test_each_vehicle_has_its_truth_file_and_faults_address_one_vehicle(tmp_path):
    sc = variant(tmp_path, "office", fleet(2) + '[[faults]]\nkind = "byte_drop"\nport = "sins2"\n'
                 'probability = 0.5\n', "t")
    w = World(sc, 4)
    assert [v.number for v in w.vehicles] == [1, 2]
    with Emulation(sc, 4, speed=None, ports=False, duration_s=2.0, record=tmp_path / "rec") as emu:
        summary = emu.run()
    truth2 = (tmp_path / "rec" / "truth2.csv").read_bytes()
    assert truth2 == HEADER + csv_rows(w.truth(0, 2 * 10**9, 2))  # vehicle 2's own line
    assert truth2 != (tmp_path / "rec" / "truth.csv").read_bytes()
    assert summary["ports"]["sins2"]["bytes"] < summary["ports"]["sins"]["bytes"]  # dropped there only
    assert summary["ports"]["sins"]["bytes"] == 200 * 30


def test_a_convoy_copies_vehicle_1_with_its_own_tag_router_and_start():
    from navtwin.emulator.fleet import convoy

    office = load_scenario("office")
    sc = convoy(office, 4, network="per-vehicle")
    assert [v.tag.id for v in sc.fleet] == [16, 17, 18, 19]
    assert [v.router.SL - office.xbee.router.SL for v in sc.fleet] == [0, 1, 2, 3]
    assert [v.trajectory.alignment_s - office.trajectory.alignment_s for v in sc.fleet] == [0, 2, 4, 6]
    assert sc.fleet[3].imu == office.imu and sc.xbee.network == sc.ranging.network == "per-vehicle"
    assert convoy(office, 1) == office
    with pytest.raises(ScenarioError, match="already has 4 vehicles"):
        convoy(sc, 2)


def test_emulate_runs_a_convoy_with_ports_per_vehicle(tmp_path):
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "navtwin", "emulate", "--scenario", "office",
                          "--vehicles", "2", "--network", "per-vehicle", "--speed", "max",
                          "--duration", "1", "--quiet", "--link-dir", str(tmp_path / "l")],
                         capture_output=True, text=True, timeout=120, check=True)
    ready, done = (json.loads(line) for line in out.stdout.splitlines())
    assert list(ready["ports"]) == ["sins", "xbee", "nanoloc", "sins2", "xbee2", "nanoloc2"]
    assert done["ports"]["sins2"]["frames"] == done["ports"]["sins"]["frames"] == 100


def test_the_shipped_convoy_is_the_office_with_two_more_cars():
    """office-convoy writes out what `--vehicles 3` makes of the office."""
    import dataclasses

    from navtwin.emulator.fleet import convoy

    shipped = load_scenario("office-convoy")
    made = convoy(load_scenario("office"), 3)
    assert dataclasses.replace(made, name=shipped.name, description=shipped.description) == shipped


@pytest.mark.parametrize("network", ["shared", "per-vehicle"])
def test_every_cars_bytes_are_the_same_paced_and_at_max_speed(tmp_path, network):
    """Same scenario and seed, identical bytes on every port of every car at every speed,
    with the channel's waits and drops (shared) or a coordinator per car."""
    from navtwin.emulator.fleet import convoy
    from navtwin.protocols.recording import Recording

    sc = convoy(load_scenario("office"), 3, network=network)
    recs = []
    for name, speed in (("max", None), ("x20", 20.0)):
        with Emulation(sc, 5, speed=speed, ports=False, duration_s=3.0, record=tmp_path / name) as emu:
            emu.run()
        recs.append(Recording(tmp_path / name))
    assert sorted(recs[0].ports) == sorted(recs[1].ports) == sorted(sc.ports)
    for port in sc.ports:
        assert recs[0].read_bytes(port) == recs[1].read_bytes(port), port
        assert [c.t_device_ns for c in recs[0].chunks(port)] == [c.t_device_ns for c in recs[1].chunks(port)]
    for n in (1, 2, 3):
        name = "truth.csv" if n == 1 else f"truth{n}.csv"
        assert (tmp_path / "max" / name).read_bytes() == (tmp_path / "x20" / name).read_bytes()
