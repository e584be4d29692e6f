"""The paced loop's timers (emulator.schedule): deadlines in order, a timer re-keyed when it
changes."""
from __future__ import annotations

from navtwin.emulator.fleet import convoy
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.schedule import Deadlines, Turns
from navtwin.emulator.uart import Line, Wire
from navtwin.emulator.world import World


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
    assert d.next() == 1_000  # the chunk starts
    assert d.due(1_000) == ["sins"]
    line.poll(1_000, 10**9, 10**9)
    assert d.next() == line.next_ns() > 1_000  # now: its end


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
