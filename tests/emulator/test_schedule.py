"""The paced loop's timers (emulator.schedule): deadlines in order, a timer re-keyed when it
changes."""
from __future__ import annotations

import numpy as np

from navtwin.emulator.fleet import convoy
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.schedule import Deadlines, Turns
from navtwin.emulator.uart import Line, Marked, Wire
from navtwin.protocols.serial import wire_ns
from navtwin.emulator.world import World


class _Moody(Wire):
    """A device whose frames depend on a mode the host sets (as the coordinator's AO does)."""

    def __init__(self):
        super().__init__(115200)
        self.mode = 0

    def render(self, t, item):
        return bytes([self.mode]) * self.mode + item

    def size(self, t, item):
        return len(self.render(t, item))


class Timer:
    def __init__(self, t):
        self.t = t

    def next_ns(self):
        return self.t


def test_deadlines_come_in_time_order_and_only_when_due():
    timers = {"a": Timer(30), "b": Timer(10), "c": Timer(None), "d": Timer(20)}
    d = Deadlines(timers)
    assert d.next() == 10
    assert d.due(5) == []
    assert d.due(25) == ["b", "d"]
    assert d.next() == 10  # handed out = touched: asked again, and they have not moved
    timers["b"].t, timers["d"].t = 40, None
    assert d.next() == 10  # not touched since it was asked: the old key stands
    assert d.due(25) == ["b", "d"]
    assert d.next() == 30
    assert d.due(100) == ["a", "b"]


def test_a_timer_is_rekeyed_when_touched_and_stale_entries_are_dropped():
    timers = {"a": Timer(50), "b": Timer(60)}
    d = Deadlines(timers)
    assert d.next() == 50
    timers["a"].t = 70
    d.touch("a")
    assert d.next() == 60  # a's entry at 50 is stale
    timers["a"].t = 5
    d.touch("a")
    assert d.due(10) == ["a"]
    timers["a"].t = None
    assert d.due(1000) == ["b"]  # a touched by due(): asked again, now nothing to do
    assert d.next() == 60  # b handed out and not polled: still due at 60


def test_a_line_gets_a_deadline_when_it_gets_a_chunk():
    line = Line("sins", Wire(115200))
    d = Deadlines({"sins": line})
    assert d.next() is None
    line.put(1_000, b"x" * 10)
    d.touch("sins")
    assert d.next() == 1_000  # the chunk starts (a wire's: in the burst of every car's)
    assert d.due(1_000) == ["sins"]
    line.poll(1_000, 10**9, 10**9)
    assert d.next() == line.next_ns() > 1_000  # now: its end


def test_a_device_that_tells_the_size_gets_the_deadline_of_the_chunks_end():
    """A device that can say what it will render (the coordinator's RF packets) gives the
    line the deadline of the chunk's end, and the poll there takes the start too; a marked
    item (its ledger entry) or a device without size gets the deadline of its start."""
    line = Line("xbee", _Moody())
    d = Deadlines({"xbee": line})
    line.put(1_000, b"x" * 10)
    d.touch("xbee")
    end = 1_000 + wire_ns(10, 115200)
    assert d.next() == end
    assert d.due(end - 1) == []
    assert d.due(end) == ["xbee"]
    assert [c.end_ns for c in line.poll(end, 10**9, 10**9)] == [end]
    assert d.next() is None
    line = Line("xbee", _Moody())
    line.put(1_000, Marked(b"x" * 10, ({"kind": "k"},)))
    assert line.next_ns() == 1_000
    line = Line("xbee", Wire(115200))
    line.put(1_000, b"x" * 10)
    assert line.next_ns() == 1_000


def test_catch_up_takes_the_steps_and_keeps_the_chunks_for_the_poll():
    """A change from outside the timeline at t finds the line as a poll at every step
    would: the chunk that started before t is on the wire, and the chunks that ended are
    given by the next poll, in order."""
    line = Line("xbee", _Moody())
    line.put(0, b"a" * 10)
    line.put(10, b"b" * 10)
    a_end = wire_ns(10, 115200)
    line.catch_up(a_end + 1, 10**9, 10**9)
    assert line.current is not None and line.current.data == b"b" * 10  # started at a's end
    assert line.next_ns() == a_end  # the ended chunk waits: due at once
    assert line.busy(10**9)
    out = line.poll(2 * a_end, 10**9, 10**9)
    assert [c.data for c in out] == [b"a" * 10, b"b" * 10]
    assert not line.busy(10**9)


def test_a_wrapper_due_later_does_not_hide_an_item_due_now():
    """The loop polls a line only at its next_ns: an item arriving on an idle line must set
    it, even with a wrapper that will release bytes much later (a garbage fault's burst)."""
    from navtwin.emulator.uart import LineWrapper

    class Later(LineWrapper):
        def due_ns(self):
            return 5_000_000_000

    line = Line("xbee", Wire(115200), [Later()])
    assert line.next_ns() == 5_000_000_000
    line.put(1_000, b"reply")
    assert line.next_ns() == 1_000


def test_turns_spread_each_item_once_a_period():
    """Each of 4 items once every 100 ns, the first round at once, then one item every 25
    ns of the wake-ups' times; a stalled loop looks at each item once, not once a period
    missed; next_ns keeps every item within a period of its slot."""
    t = Turns("abcd", 100, 1000)
    assert t.due(999) == []
    assert t.due(1000) == list("abcd")  # the first round before anything else
    assert t.next_ns == 1125  # a's next slot (1025) plus a period
    assert t.due(1010) == []
    assert t.due(1025) == ["a"]
    assert t.due(1074) == ["b"]
    assert t.next_ns == 1175  # c's slot (1075) plus a period
    looked = []
    for now in range(1075, 1500, 7):  # wake-ups every 7 ns: a, b, c, d in turn, in time
        looked += t.due(now)
    assert looked == list("cd" + "abcd" * 3 + "abc")
    assert t.due(5000) == list("abcd")  # a stall of 35 periods: each once
    assert t.due(5000) == []
    assert Turns([], 100, 0).due(10**9) == []


def _played(lazy: bool, items, changes) -> list:
    """Chunks of a line given *items* (t, bytes), the host setting the mode at *changes*
    (t, mode); lazy: polled only at next_ns, caught up before each change; else polled at
    every instant anything happens (an arrival, a chunk's end, a change), as the loop did
    when it woke at every chunk's start."""
    device = _Moody()
    line = Line("xbee", device)
    for t, data in items:
        line.put(t, data)
    out, changes, known = [], list(changes), 10**12
    arrivals = sorted({t for t, _ in items})
    while True:
        if lazy:
            t = line.next_ns()
        else:
            ahead = arrivals[:1] + ([line.current.end_ns] if line.current is not None else [])
            t = min(ahead) if ahead else None
        if changes and (t is None or changes[0][0] <= t):
            at, mode = changes.pop(0)
            if lazy:
                line.catch_up(at, known, known)
            else:
                out += line.poll(at, known, known)
            device.mode = mode
            continue
        if t is None:
            return out
        out += line.poll(t, known, known)
        arrivals = [a for a in arrivals if a > t]


def test_looking_ahead_gives_the_chunks_of_a_poll_at_every_step():
    """The loop that wakes only at chunks' ends, catching the line up before each change
    from the host, writes what a loop polling at every instant writes: the same bytes at
    the same times, whatever the changes' times (before, during or after a chunk)."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        t = np.cumsum(rng.integers(1, 3_000_000, 30))
        items = [(int(a), bytes(rng.integers(0, 256, int(n)).astype(np.uint8)))
                 for a, n in zip(t, rng.integers(1, 40, 30))]
        changes = sorted((int(c), int(m)) for c, m in zip(
            rng.integers(0, int(t[-1]) + 5_000_000, 6), rng.integers(0, 5, 6)))
        lazy, eager = _played(True, items, changes), _played(False, items, changes)
        assert [(c.start_ns, c.end_ns, c.data) for c in lazy] == \
            [(c.start_ns, c.end_ns, c.data) for c in eager]
        assert len(lazy) == len(items)
