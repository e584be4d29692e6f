"""The 2.4 GHz channel that the routers of one network share: one packet on the air at a time.

Each router's link (emulator.radio) sends its own packets one at a time; routers that joined
one coordinator ([xbee] network = "shared") also wait for each other, as their CSMA-CA does
when it hears the channel busy. :class:`Channel` serves every router's packets of a block
first come, first served (by when each would have taken the radio, then vehicle order), each
holding the channel for its service time (its attempts, backoffs, ACKs and ACK waits: the
link's draws, so the channel adds no random draw); a packet that waits has its arrival at the
coordinator and its frames on the air moved by the wait. A router queues at most
``TX_QUEUE`` packets (Digi: "the TX queue holds about 4 messages"; xbee-api-facts.md
section 5): a packet that comes while its router has that many waiting or on the air is
dropped at the router and counted (``dropped_channel`` of the coordinator's port). A
router of the office lab holds the channel about 0.37 of the time (100 packets/s, each a
1.1 ms mean backoff, 2.0 ms of airtime and a 0.54 ms ACK), so a shared channel fills at
about 2.7 routers, and the coordinator's UART (115200 baud, emulator.coordinator) at about
2.4 routers' streams: `navtwin emulate --scenario office --vehicles N --speed max --duration
20` drops nothing at N = 2; at N = 3 the routers' queues drop 621 packets of 6000 and the
UART 469 more.

Left out: collisions (carrier sense is taken as perfect), the coordinator's own transmit
requests and the networks of other coordinators (a network per vehicle is taken to be on a
channel of its own).
"""
from __future__ import annotations

from collections import deque
from typing import NamedTuple

TX_QUEUE = 4  # packets a router holds for the channel (module doc)


class Offered(NamedTuple):
    """One router's packet offered to the channel: when it would take the radio alone, how
    long it holds it, and what it becomes (its event at the coordinator, None when the link
    lost it; its frames on the air)."""

    vehicle: int
    start_ns: int
    service_ns: int
    event: object
    air: list


class Channel:
    """The shared channel of one network (module doc)."""

    def __init__(self) -> None:
        self.free_ns = 0  # the channel is busy before this
        self.dropped = 0  # packets dropped by full router queues
        self._queued: dict[int, deque] = {}  # per vehicle: when its accepted packets end

    def share(self, offered: list[Offered]) -> tuple[list, list]:
        """The events and air frames of the block's *offered* packets, each moved by its
        wait for the channel, less the packets dropped at their router."""
        events, air = [], []
        for p in sorted(offered, key=lambda p: (p.start_ns, p.vehicle)):
            queue = self._queued.setdefault(p.vehicle, deque())
            while queue and queue[0] <= p.start_ns:
                queue.popleft()
            if len(queue) >= TX_QUEUE:
                self.dropped += 1
                continue
            begin = max(p.start_ns, self.free_ns)
            self.free_ns = begin + p.service_ns
            queue.append(self.free_ns)
            wait = begin - p.start_ns
            if p.event is not None:
                events.append(p.event._replace(t_ns=p.event.t_ns + wait) if wait else p.event)
            air += [f._replace(t_ns=f.t_ns + wait) for f in p.air] if wait else p.air
        return events, air
