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

from .crc import crc16

HEADER = 4  # sync + type + len
TRAILER = 2  # crc


def encode(sync: bytes, ftype: int, payload: bytes) -> bytes:
    """A whole frame around *payload*: the fast builder, equal to the construct build."""
    body = bytes((ftype, len(payload))) + payload
    c = crc16(body)
    return sync + body + bytes((c >> 8, c & 0xFF))


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
