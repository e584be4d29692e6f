"""What the world's devices make: timed events on their ports (emulator.world), made in the
run's process or by its maker process (emulator.maker)."""
from __future__ import annotations

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
