"""The lab's serial lines: 8N1 framing and the rates a port can be set to.

Every line of the lab is 8N1: a start bit, 8 data bits and a stop bit, so a byte occupies
10 bit times. Both sides time bytes with :func:`wire_ns`: the emulator's UARTs, and the
host's replay of an emulator recording (when a chunk's last byte has arrived). Device models
that place single bytes in time (the board's bytes at the router, the gateway's report
length, the router's RO timeout) use the unrounded :func:`char_ns` of the same framing.
"""
from __future__ import annotations

BITS_PER_BYTE = 10  # 8N1
SEC = 1_000_000_000
#: Rates from 50 (the lowest termios rate; B0 would hang the line up) to 4 Mbit/s (the highest
#: Linux rate; pyserial sets any rate between, as the XBee's BD accepts non-standard ones).
BAUDS = (50, 4_000_000)


def wire_ns(nbytes: int, baud: int) -> int:
    """Time on the wire of *nbytes* at *baud*, in integer nanoseconds (rounded)."""
    return (nbytes * BITS_PER_BYTE * SEC + baud // 2) // baud


def char_ns(baud: int) -> float:
    """Time on the wire of one byte at *baud*, ns, unrounded (models round their own sums)."""
    return BITS_PER_BYTE * SEC / baud
