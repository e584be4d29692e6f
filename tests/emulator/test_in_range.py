"""The in-range TDMA schedule and the cycle's sampling-time error (emulator.tdma) on
outage-bridging's field of 1402 anchors: who exchanges in each cycle and in which slot, the
jittered starts, the wide reports, and the same bytes however time is cut or paced."""
import dataclasses
import math

import numpy as np
import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import ScenarioError, load_scenario, parse_scenario
from navtwin.emulator.world import World
from navtwin.protocols import nanoloc
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import Frame, nanoloc_decoder

SEC = 1_000_000_000


@pytest.fixture(scope="module")
def field():
    sc = load_scenario("outage-bridging")
    events = World(sc, 4).advance(120 * SEC)
    reports = nanoloc_decoder().decode(b"".join(e.data for e in events if e.port == "nanoloc"))
    assert all(isinstance(f, Frame) for f in reports)
    return sc, events, reports


def _cycles(reports) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = {}
    for f in reports:
        out.setdefault(f.fields["t_us"] // 1_000_000, []).append(f.fields)
    return out


def test_each_cycle_the_anchors_in_range_take_the_slots_nearest_first(field):
    sc, _, reports = field
    anchors = {a.id: np.array(sc.anchor_position(a)) for a in sc.all_anchors}
    traj = World(sc, 4).vehicles[0].trajectory
    scale = 1 + sc.clocks.network_ppm * 1e-6
    cycles = _cycles(reports)
    assert len(cycles) > 100
    dropped = 0
    for got in cycles.values():
        start_us = got[0]["t_us"]  # slot 0 is the nearest anchor, in range then and 0 s later
        tag = traj.position(np.array([round(start_us * 1e3 / scale)]))[0]
        dist = {i: float(np.linalg.norm(p - tag)) for i, p in anchors.items()}
        expect = sorted((i for i in anchors if dist[i] <= 11.0), key=lambda i: (dist[i], i))[:40]
        # slot i of the list at the cycle start exchanges 25 i ms later; the gateway drops it
        # when the tag has left its range by then (emulator.nanoloc)
        slots = {r["anchor"]: (r["t_us"] - start_us) / 25_000 for r in got}
        assert all(slots[a] == pytest.approx(expect.index(a), abs=1e-4) for a in slots)
        for i, a in enumerate(expect):
            if a not in slots:
                at = traj.position(np.array([round((start_us + 25_000 * i) * 1e3 / scale)]))[0]
                assert np.linalg.norm(anchors[a] - at) > 11.0
                dropped += 1
    assert dropped < 0.05 * len(reports)
    assert {f.fields["tag"] for f in reports} == {1000}


def test_only_the_anchors_in_range_draw_and_the_reports_are_wide(field):
    sc, events, reports = field
    inside = [len(v) for k, v in _cycles(reports).items() if 15 <= k <= 95]  # in area 1
    assert 10 <= min(inside) and max(inside) <= 25
    assert {f.type for f in reports} == {nanoloc.TYPE_WIDE_RANGING}
    assert all(len(e.data) == nanoloc.WIDE_FRAME_SIZE for e in events if e.port == "nanoloc")
    office = World(load_scenario("office")).advance(2 * SEC)
    assert {e.data[2] for e in office if e.port == "nanoloc"} == {nanoloc.TYPE_RANGING}


def test_cycle_starts_carry_the_sampling_time_error(field):
    sc, _, reports = field
    starts = np.array([v[0]["t_us"] for v in _cycles(reports).values()])
    nominal = sc.ranging.start_ms * 1e3 + np.round((starts - sc.ranging.start_ms * 1e3) / 1e6) * 1e6
    delta_ms = (starts - nominal) / 1e3
    assert 0.7 < np.std(delta_ms) < 1.3 and abs(np.mean(delta_ms)) < 0.3
    steady = dataclasses.replace(sc, ranging=dataclasses.replace(sc.ranging, cycle_jitter_ms=0.0))
    events = World(steady, 4).advance(20 * SEC)
    plain = nanoloc_decoder().decode(b"".join(e.data for e in events if e.port == "nanoloc"))
    assert {f.fields["t_us"] % 25_000 for f in plain} == {sc.ranging.start_ms * 1e3}


@pytest.mark.parametrize("step_ns", [1_000_000, 333_333_333, 7 * SEC])
def test_slicing_never_changes_the_events(field, step_ns):
    sc, events, _ = field
    w, got, t = World(sc, 4), [], 0
    while t < 120 * SEC:
        t = min(t + step_ns, 120 * SEC)
        got += w.advance(t)
    assert [(e.t_ns, e.port, e.data) for e in got] == [(e.t_ns, e.port, e.data) for e in events]


def test_paced_and_max_speed_give_identical_recordings(tmp_path):
    sc = load_scenario("outage-bridging")
    recs = []
    for name, speed in (("max", None), ("x25", 25.0)):
        with Emulation(sc, 4, speed=speed, ports=False, duration_s=2.5, record=tmp_path / name) as emu:
            emu.run()
        recs.append(Recording(tmp_path / name))
    for port in ("sins", "nanoloc", "xbee"):
        assert recs[0].read_bytes(port) == recs[1].read_bytes(port)
    assert recs[0].read_bytes("nanoloc")


@pytest.mark.parametrize("ranging, message", [
    ({"schedule": "in-range"}, r"\[ranging\] radio_range_m is needed with schedule = \"in-range\""),
    ({"schedule": "in-range", "radio_range_m": 11.0, "anchor_exchange_every_cycles": 5},
     r"\[ranging\] schedule \"in-range\" gives the slots by distance"),
    ({"schedule": "near"}, r"\[ranging\] schedule must be one of"),
])
def test_bad_schedules_are_one_line_errors(ranging, message):
    import tomllib
    doc = tomllib.loads(load_scenario("office").to_toml())
    doc["ranging"].update(ranging)
    doc["ranging"].pop("radio_range_m", None) if "radio_range_m" not in ranging else None
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(doc)


def test_the_field_starts_quickly():
    """1402 anchors: no generator until an anchor's first exchange."""
    sc = load_scenario("outage-bridging")
    net = World(sc, 4).nanoloc
    assert len(net.anchors) == 1402 and all(a._rng is None for a in net.anchors)
    assert math.floor(sc.ranging.cycle_ms / sc.ranging.slot_ms) == net.schedule.slots == 40
