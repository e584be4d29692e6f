"""The quick path of an in-memory run (Emulation.chunks, uart.Line.drain): each line timed in
one pass, equal to what the timeline's steps hand a sink, or refused."""
from __future__ import annotations

import numpy as np
import pytest

from navtwin.emulator.runner import Emulation, chunks_together
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.shipped import NAMES
from navtwin.emulator.uart import Drained, Irregular, Line, LineWrapper, Marked, Wire
from navtwin.lab import run as lab_run
from navtwin.lab.run import lab_ports
from navtwin.protocols.serial import wire_ns

from .test_vehicles import fleet
from .world_helpers import variant

SEC = 1_000_000_000


class _Bounded(Wire):
    """A device with a transmit buffer of *room* bytes that drops what does not fit, as the
    coordinator's admit does; each item's bytes are the item."""

    def __init__(self, room: int) -> None:
        super().__init__(115200)
        self.room = room
        self.dropped = 0

    def admit(self, t_ns, item, queued):
        if queued + len(item) > self.room:
            self.dropped += 1
            return None
        return len(item)


def _polled(items, device, end_ns, steps):
    """The line's chunks by the timeline's steps: polled at *steps* (the items known up to
    each step's time, as the loop puts a block's events), then to the end."""
    line, out, at = Line("x", device), [], 0
    for now in steps + [4 * end_ns]:
        while at < len(items) and items[at][0] < now:
            line.put(*items[at])
            at += 1
        out += line.poll(now, now if at < len(items) else 4 * end_ns, end_ns)
    return Drained(b"".join(c.data for c in out), [len(c.data) for c in out], [c.start_ns for c in out])


@pytest.mark.parametrize("seed", range(6))
def test_a_drained_line_sends_what_polling_it_sends(seed):
    """Random items, bursts that fill a bounded buffer (drops), items of nothing, and an end
    that cuts the run: the same chunks, the same starts, the same drops."""
    rng = np.random.default_rng(seed)
    n = 400
    ready = np.sort(rng.integers(0, SEC, n))
    ready[50:60] = ready[50]  # a burst at one instant
    sizes = rng.integers(0, 40, n)
    items = [(int(t), bytes([k % 256]) * int(s)) for k, (t, s) in enumerate(zip(ready, sizes))]
    end_ns = int(0.8 * SEC)
    polled_device, drained_device = _Bounded(120), _Bounded(120)
    steps = sorted(rng.integers(0, end_ns, 20).tolist())
    want = _polled(items, polled_device, end_ns, steps)
    line = Line("x", drained_device)
    for item in items:
        line.put(*item)
    assert line.drain(end_ns) == want
    assert drained_device.dropped == polled_device.dropped > 0


class _Counted(_Bounded):
    """_Bounded, counting the items it admits one at a time (Line.drain's item-by-item pass)."""

    def __init__(self, room) -> None:
        super().__init__(room)
        self.admitted = 0

    def admit(self, t_ns, item, queued):
        self.admitted += 1
        return super().admit(t_ns, item, queued) if self.room is not None else len(item)


@pytest.mark.parametrize("room, one_by_one", [(None, False), (2000, False), (120, True)])
def test_a_line_rendered_at_once_is_timed_as_polling_times_it(room, one_by_one):
    """The running-maximum timing (render_all) against the timeline's steps: items of
    nothing, bursts, a cut at the end; a buffer that would drop an item sends the line
    item by item instead, with the same drops."""
    rng = np.random.default_rng(7)
    ready = np.sort(rng.integers(0, SEC, 300))
    ready[100:120] = ready[100]
    items = [(int(t), bytes([k % 256]) * int(s))
             for k, (t, s) in enumerate(zip(ready, rng.integers(0, 30, 300)))]
    end_ns = int(0.7 * SEC)
    polled, drained = _Counted(room), _Counted(room)
    want = _polled(items, polled, end_ns, sorted(rng.integers(0, end_ns, 15).tolist()))
    line = Line("x", drained)
    for item in items:
        line.put(*item)
    assert line.drain(end_ns) == want and len(want.sizes) > 100
    assert (drained.admitted > 0) == one_by_one and drained.dropped == polled.dropped
    assert line.chunks == len(want.sizes) and line.delivered == len(want.data)


def test_a_chunk_that_ends_as_an_item_arrives_has_left_the_buffer():
    """The tie as poll takes it: the end first, so the item finds the buffer empty."""
    end = wire_ns(30, 115200)
    items = [(0, b"a" * 30), (end, b"b" * 10)]
    line = Line("x", _Bounded(35))
    for item in items:
        line.put(*item)
    assert line.drain(SEC) == _polled(items, _Bounded(35), SEC, []) == (b"a" * 30 + b"b" * 10, [30, 10], [0, end])


def test_a_line_with_wrappers_marks_or_history_is_not_drained():
    wrapped = Line("x", Wire(115200), [LineWrapper()])
    with pytest.raises(Irregular):
        wrapped.drain(SEC)
    marked = Line("x", Wire(115200))
    marked.put(0, Marked(b"a", ({"kind": "k"},)))
    with pytest.raises(Irregular):
        marked.drain(SEC)
    used = Line("x", Wire(115200))
    used.put(0, b"a")
    used.poll(SEC, SEC, SEC)
    with pytest.raises(Irregular):
        used.drain(SEC)


def _sunk(sc, seed, duration):
    return lab_run._sunk(sc, seed, duration, [p for p, _ in sc.instances()])


def _quick(sc, seed, duration):
    with Emulation(sc, seed, speed=None, duration_s=duration, ports=False) as emu:
        return emu.chunks(list(emu.lines))


@pytest.mark.parametrize("name", [n for n in NAMES if not load_scenario(n).faults])
def test_every_shipped_scenario_without_faults_is_timed_as_the_timeline_times_it(name):
    sc = load_scenario(name)
    assert _quick(sc, 3, 12.0) == _sunk(sc, 3, 12.0)


def test_four_routers_overflowing_one_coordinator_are_dropped_alike(tmp_path):
    sc = variant(tmp_path, "office", fleet(4), "four")
    quick = _quick(sc, 1, 20.0)
    assert quick == _sunk(sc, 1, 20.0)
    with Emulation(sc, 1, speed=None, duration_s=20.0, ports=False) as emu:
        emu.chunks(["xbee"])
        assert emu.devices["xbee"].stats()["dropped_tx_buffer"] > 0


def test_the_ports_not_taken_are_left_alone_and_the_rest_unchanged():
    sc = load_scenario("office")
    with Emulation(sc, 2, speed=None, duration_s=5.0, ports=False) as emu:
        some = emu.chunks(["xbee"])
        assert emu.lines["sins"].chunks == 0 and emu.lines["nanoloc"].chunks == 0
    assert some["xbee"] == _quick(sc, 2, 5.0)["xbee"]


def test_a_scenario_with_faults_is_refused_and_lab_ports_runs_the_timeline():
    sc = load_scenario("corridor-outage")
    assert sc.faults
    with Emulation(sc, 1, speed=None, duration_s=5.0, ports=False) as emu:
        with pytest.raises(Irregular, match="faults"):
            emu.chunks(["xbee"])
    _, ports, _ = lab_ports(sc, 1, duration=5.0)
    sunk = _sunk(sc, 1, 5.0)
    for port, (data, sizes, starts) in ports.items():
        assert (data, sizes.tolist(), starts.tolist()) == sunk[port]


def test_seeds_run_together_give_each_seeds_chunks_alone():
    """chunks_together (the seeds' worlds in step, their IMU blocks on one seed axis)."""
    sc = load_scenario("office")
    alone = [_quick(sc, seed, 6.0) for seed in (1, 2, 3)]
    runs = [Emulation(sc, seed, speed=None, duration_s=6.0, ports=False) for seed in (1, 2, 3)]
    assert chunks_together(runs, list(runs[0].lines)) == alone
    assert alone[0] != alone[1]
