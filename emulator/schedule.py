"""The paced loop's timers: each UART line's next step, in a heap of deadlines.

With many vehicles an emulation has hundreds of lines (sins<n>, xbee<n>, nanoloc<n>, and
what the host writes to each coordinator). Asking every line for its next step on every
wake-up makes a wake-up cost O(lines); :class:`Deadlines` keeps the earliest step of each in
a heap, so a wake-up costs O(what is due) and O(log lines) per line that changed.

A timer is any object with ``next_ns()`` (emulator.uart ``Line`` and ``Inbound``): when it
next has something to do, or None. Its answer changes only when the timer is changed: an
item put on the line, a poll, a wrapper added or removed. The caller says so with
:meth:`Deadlines.touch`; the timer is asked again (re-keyed) before the next :meth:`due` or
:meth:`next`. A name that :meth:`due` hands out is touched, since the caller polls it.

Re-keying leaves the old heap entry where it is; an entry is current only while it equals
the timer's key, and stale ones are dropped when they reach the top (lazy deletion, as in
the ``heapq`` documentation's priority queue).
"""
from __future__ import annotations

import heapq


class Deadlines:
    """The timers of *timers* (name -> timer) by their next deadline."""

    def __init__(self, timers: dict) -> None:
        self._timers = timers
        self._heap: list[tuple[int, str]] = []  # (deadline, name), current or stale
        self._key: dict[str, int | None] = dict.fromkeys(timers)  # name -> deadline in the heap
        self._touched: set[str] = set(timers)  # to be asked again

    def touch(self, name: str) -> None:
        """Timer *name* changed: ask it for its deadline again."""
        self._touched.add(name)

    def _rekey(self) -> None:
        key, heap = self._key, self._heap
        for name in self._touched:
            t = self._timers[name].next_ns()
            if t != key[name]:
                key[name] = t
                if t is not None:
                    heapq.heappush(heap, (t, name))
        self._touched.clear()

    def due(self, now_ns: int) -> list[str]:
        """The names whose deadline is at or before *now_ns*, in deadline order; each is
        touched (the caller polls it, which changes its deadline)."""
        self._rekey()
        heap, key, out = self._heap, self._key, []
        while heap and heap[0][0] <= now_ns:
            t, name = heapq.heappop(heap)
            if key[name] == t:  # current, not a stale entry
                key[name] = None
                out.append(name)
        self._touched.update(out)
        return out

    def next(self) -> int | None:
        """The earliest deadline of any timer, or None when none has one."""
        self._rekey()
        heap, key = self._heap, self._key
        while heap and key[heap[0][1]] != heap[0][0]:
            heapq.heappop(heap)  # stale
        return heap[0][0] if heap else None


class Turns:
    """Items looked at in turns, each once every *period_ns*: the first round all at
    *start_ns*, then turn k (k >= n) at ``start + (k - n + 1) period / n``, and :meth:`due`
    gives those whose slot has come. So the looks are spread over the wake-ups the loop has
    anyway, a few at each: the ports' ``tcgetattr``, every port's at once every 10 ms, held
    up the writes due meanwhile."""

    def __init__(self, items, period_ns: int, start_ns: int) -> None:
        self.items = list(items)
        self.period_ns = period_ns
        self._start = start_ns
        self._taken = 0  # turns taken (the slots of turns before this have been served)

    def _slot(self, k: int) -> int:
        n = len(self.items)
        return self._start + max(k - n + 1, 0) * self.period_ns // n

    def due(self, now_ns: int) -> list:
        """The items whose turn has come by *now_ns* and has not been taken, each at most
        once (a loop that stalled for several periods looks at each once, not each time)."""
        n = len(self.items)
        if not n or now_ns < self._start:
            return []
        came = n + (now_ns - self._start) * n // self.period_ns
        first = max(self._taken, came - n)
        self._taken = max(self._taken, came)
        return [self.items[k % n] for k in range(first, came)]

    @property
    def next_ns(self) -> int:
        """The latest wake-up that keeps every item within a period of its slot (a loop
        woken more often takes the turns as their slots come)."""
        if not self.items:
            return self._start
        return self._slot(self._taken) + (self.period_ns if self._taken >= len(self.items) else 0)
