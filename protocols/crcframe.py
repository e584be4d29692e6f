"""The framing shared by the SINS board frame and the nanoLOC gateway report.

| offset | size | field   |
|--------|------|---------|
| 0      | 2    | sync    |
| 2      | 1    | type    |
| 3      | 1    | len     |
| 4      | len  | payload |
| 4+len  | 2    | crc     |  CRC-16/CCITT-FALSE over type, len and payload

Unknown types are kept as raw payload bytes, so a reader can skip them by ``len``.
"""
from construct import (Checksum, Const, GreedyBytes, Int8ub, Int16ub, Prefixed, RawCopy, Struct,
                       Switch, this)

import numpy as np

from .crc import crc16, crc16_rows

HEADER = 4  # sync + type + len
TRAILER = 2  # crc


def encode(sync: bytes, ftype: int, payload: bytes) -> bytes:
    """A whole frame around *payload*: the fast builder, equal to the construct build."""
    body = bytes((ftype, len(payload))) + payload
    c = crc16(body)
    return sync + body + bytes((c >> 8, c & 0xFF))


def encode_rows(sync: bytes, ftype: int, payloads: np.ndarray) -> np.ndarray:
    """The frames around the rows of *payloads* ((n, len) uint8), one a row: :func:`encode`
    of each, the CRCs column by column (protocols.crc.RowsCrc)."""
    n, size = payloads.shape
    out = np.empty((n, HEADER + size + TRAILER), dtype=np.uint8)
    out[:, :2] = np.frombuffer(sync, dtype=np.uint8)
    out[:, 2:4] = (ftype, size)
    out[:, HEADER:-TRAILER] = payloads
    c = crc16_rows(out[:, 2:-TRAILER])
    out[:, -2], out[:, -1] = c >> 8, c & 0xFF
    return out


def crc_framed(sync: bytes, payloads: dict):
    """Declare a frame with *sync* whose payload layout is chosen by type from *payloads*."""
    return Struct(
        "sync" / Const(sync),
        "body" / RawCopy(Struct(
            "type" / Int8ub,
            "payload" / Prefixed(Int8ub, Switch(this.type, payloads, default=GreedyBytes)),
        )),
        "crc" / Checksum(Int16ub, crc16, this.body.data),
    )
