"""What the world's devices make: timed events on their ports (emulator.world), made in the
run's process or by its maker process (emulator.maker)."""
from __future__ import annotations

from itertools import repeat
from typing import NamedTuple


class RfPacket(NamedTuple):
    src64: int
    src16: int
    options: int
    data: bytes


class Event(NamedTuple):
    t_ns: int
    port: str
    data: bytes | RfPacket
    marks: tuple = ()  # ledger marks of the device faults that changed it (emulator.uart.Marked)


def rows(cls, *columns) -> list:
    """``[cls(*values) for values in zip(*columns)]`` for a NamedTuple *cls*, made by
    ``tuple.__new__`` in C: the class's own ``__new__`` is a Python call, twice the time (a
    block makes a few hundred events and frames on the air)."""
    return list(map(tuple.__new__, repeat(cls), zip(*columns)))
