"""Named random streams: one seeded numpy Generator per consumer.

Every device or model that draws random numbers owns a Generator spawned from
``SeedSequence(seed)`` with a spawn key derived from its fixed name (CRC-32 of the name),
so adding a consumer, or a consumer drawing more, never shifts another's stream.
"""
from __future__ import annotations

import zlib

import numpy as np


def stream(seed: int, name: str) -> np.random.Generator:
    """The Generator named *name* of run *seed* (same seed and name -> same numbers)."""
    key = zlib.crc32(name.encode("utf-8"))
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(key,))))


def vehicles_name(vehicle: int, name: str) -> str:
    """The name of vehicle *vehicle*'s stream *name*: vehicle 1's is *name*, vehicle n's
    "vehicle<n>.<name>", so adding a vehicle never changes another's draws, and a one-vehicle
    lab draws what it always drew."""
    return name if vehicle == 1 else f"vehicle{vehicle}.{name}"
