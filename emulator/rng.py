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
