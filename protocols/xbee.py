"""Digi XBee ZB (S2B) API frames, API mode 1 (plain) and 2 (escaped).

``7E | LEN (2, big-endian) | frame data (LEN bytes: type + fields) | checksum``

checksum = 0xFF - (sum of frame data & 0xFF); length and checksum are computed on the
unescaped bytes. In API mode 2 every byte after the start delimiter that is one of
7E 7D 11 13 is sent as ``7D (b ^ 0x20)``, length and checksum included.

Frame layouts (offsets from the frame type, as in Digi's tables minus 3) are declared below,
one Struct per type, each reading like its table in ``shared/reference/xbee-api-facts.md``.
A frame type not declared here is kept as raw bytes.
"""
from __future__ import annotations

import numpy as np
from construct import (Adapter, Bytes, Checksum, Const, CString, GreedyBytes, Int8ub, Int16ub,
                       Int32ub, Int64ub, Optional, Prefixed, RawCopy, Struct, Switch, Terminated,
                       this)

START = 0x7E
ESCAPE = 0x7D
XON = 0x11
XOFF = 0x13
ESCAPED_BYTES = frozenset((START, ESCAPE, XON, XOFF))
MAX_FRAME_DATA = 0xFFFF  # what the length field can say; decoders bound it lower
_SPECIAL = np.zeros(256, dtype=bool)  # ESCAPED_BYTES as a table, for many frames at once
_SPECIAL[list(ESCAPED_BYTES)] = True

BROADCAST64 = 0x000000000000FFFF
COORDINATOR64 = 0x0000000000000000
UNKNOWN16 = 0xFFFE
DIGI_MANUFACTURER = 0x101E  # in ND answers, 0x95 frames and ZDO node descriptors

#: BD register: the standard interface rates by code 0-7; a larger BD value (0x80 up) is the
#: rate itself (a non-standard rate).
BAUD_CODES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)


def baud_rate(bd: int) -> int:
    """The UART rate for a BD value (0-7 standard codes, 0x80-0xE1000 the rate itself)."""
    return BAUD_CODES[bd] if bd < len(BAUD_CODES) else bd


class FrameType:
    AT_COMMAND = 0x08
    AT_COMMAND_QUEUE = 0x09
    TRANSMIT_REQUEST = 0x10
    EXPLICIT_ADDRESSING = 0x11
    REMOTE_AT_REQUEST = 0x17
    AT_RESPONSE = 0x88
    MODEM_STATUS = 0x8A
    TRANSMIT_STATUS = 0x8B
    RECEIVE_PACKET = 0x90
    EXPLICIT_RX = 0x91
    NODE_IDENTIFICATION = 0x95
    REMOTE_AT_RESPONSE = 0x97


FRAME_NAMES = {v: k.lower() for k, v in vars(FrameType).items() if not k.startswith("_")}


class AtStatus:
    OK = 0
    ERROR = 1
    INVALID_COMMAND = 2
    INVALID_PARAMETER = 3
    TX_FAILURE = 4


class ModemStatus:
    HARDWARE_RESET = 0x00
    WATCHDOG_RESET = 0x01
    JOINED = 0x02
    DISASSOCIATED = 0x03
    COORDINATOR_STARTED = 0x06


class DeliveryStatus:
    SUCCESS = 0x00
    MAC_ACK_FAILURE = 0x01
    CCA_FAILURE = 0x02
    NETWORK_ACK_FAILURE = 0x21
    NOT_JOINED = 0x22
    SELF_ADDRESSED = 0x23
    ADDRESS_NOT_FOUND = 0x24
    ROUTE_NOT_FOUND = 0x25
    PAYLOAD_TOO_LARGE = 0x74


AtCommand = Struct(  # 0x08 and 0x09
    "frame_id" / Int8ub,
    "command" / Bytes(2),
    "parameter" / GreedyBytes,  # absent = query
)
TransmitRequest = Struct(  # 0x10
    "frame_id" / Int8ub,
    "dest64" / Int64ub,
    "dest16" / Int16ub,
    "radius" / Int8ub,
    "options" / Int8ub,
    "data" / GreedyBytes,
)
ExplicitAddressing = Struct(  # 0x11
    "frame_id" / Int8ub,
    "dest64" / Int64ub,
    "dest16" / Int16ub,
    "src_endpoint" / Int8ub,
    "dest_endpoint" / Int8ub,
    "cluster" / Int16ub,
    "profile" / Int16ub,
    "radius" / Int8ub,
    "options" / Int8ub,
    "data" / GreedyBytes,
)
RemoteAtRequest = Struct(  # 0x17
    "frame_id" / Int8ub,
    "dest64" / Int64ub,
    "dest16" / Int16ub,
    "options" / Int8ub,
    "command" / Bytes(2),
    "parameter" / GreedyBytes,
)
AtResponse = Struct(  # 0x88
    "frame_id" / Int8ub,
    "command" / Bytes(2),
    "status" / Int8ub,
    "value" / GreedyBytes,  # omitted for a set
)
ModemStatusFrame = Struct(  # 0x8A
    "status" / Int8ub,
    Terminated,
)
TransmitStatus = Struct(  # 0x8B, always 7 bytes of frame data
    "frame_id" / Int8ub,
    "dest16" / Int16ub,
    "retries" / Int8ub,
    "delivery" / Int8ub,
    "discovery" / Int8ub,
    Terminated,
)
ReceivePacket = Struct(  # 0x90
    "src64" / Int64ub,
    "src16" / Int16ub,
    "options" / Int8ub,  # 0x01 acked, 0x02 broadcast, 0x20 encrypted, 0x40 from end device
    "data" / GreedyBytes,
)
ExplicitRx = Struct(  # 0x91
    "src64" / Int64ub,
    "src16" / Int16ub,
    "src_endpoint" / Int8ub,
    "dest_endpoint" / Int8ub,
    "cluster" / Int16ub,
    "profile" / Int16ub,
    "options" / Int8ub,
    "data" / GreedyBytes,
)
NodeIdentification = Struct(  # 0x95, ZB layout
    "src64" / Int64ub,
    "src16" / Int16ub,
    "options" / Int8ub,
    "remote16" / Int16ub,
    "remote64" / Int64ub,
    "ni" / CString("ascii"),
    "parent16" / Int16ub,
    "device_type" / Int8ub,  # 0 coordinator, 1 router, 2 end device
    "source_event" / Int8ub,
    "profile" / Int16ub,
    "manufacturer" / Int16ub,
    "device_type_id" / Optional(Int32ub),  # DD, only when NO bit 0 is set
    Terminated,
)
RemoteAtResponse = Struct(  # 0x97
    "frame_id" / Int8ub,
    "src64" / Int64ub,
    "src16" / Int16ub,
    "command" / Bytes(2),
    "status" / Int8ub,
    "value" / GreedyBytes,
)

FRAME_BODIES = {
    FrameType.AT_COMMAND: AtCommand,
    FrameType.AT_COMMAND_QUEUE: AtCommand,
    FrameType.TRANSMIT_REQUEST: TransmitRequest,
    FrameType.EXPLICIT_ADDRESSING: ExplicitAddressing,
    FrameType.REMOTE_AT_REQUEST: RemoteAtRequest,
    FrameType.AT_RESPONSE: AtResponse,
    FrameType.MODEM_STATUS: ModemStatusFrame,
    FrameType.TRANSMIT_STATUS: TransmitStatus,
    FrameType.RECEIVE_PACKET: ReceivePacket,
    FrameType.EXPLICIT_RX: ExplicitRx,
    FrameType.NODE_IDENTIFICATION: NodeIdentification,
    FrameType.REMOTE_AT_RESPONSE: RemoteAtResponse,
}

#: Frame data: the type byte, then its layout (raw bytes for a type not declared).
FrameData = Struct(
    "type" / Int8ub,
    "body" / Switch(this.type, FRAME_BODIES, default=GreedyBytes),
)


def checksum(frame_data: bytes) -> int:
    return 0xFF - (sum(frame_data) & 0xFF)


#: One API mode 1 frame.
ApiFrame = Struct(
    "start" / Const(bytes([START])),
    "frame" / RawCopy(Prefixed(Int16ub, FrameData)),
    "checksum" / Checksum(Int8ub, lambda raw: checksum(raw[2:]), this.frame.data),
)


def escape(data: bytes) -> bytes:
    """API mode 2 escaping of the bytes after the start delimiter."""
    data = bytes(data)
    # four C-level replaces; 7D first, so the 7D of the later pairs is not escaped again
    return (data.replace(b"\x7d", b"\x7d\x5d").replace(b"\x7e", b"\x7d\x5e")
            .replace(b"\x11", b"\x7d\x31").replace(b"\x13", b"\x7d\x33"))


def unescape_partial(data: bytes) -> tuple[bytes, int]:
    """Unescape the longest valid prefix of *data*: (unescaped bytes, raw bytes used).

    It stops before the first escape that is invalid (``7D`` then a byte that does not XOR
    to an escaped byte) or incomplete (``7D`` as the last byte).
    """
    escapes = data.count(ESCAPE)
    if not escapes:
        return bytes(data), len(data)
    # In valid data every 7D starts a pair and no pair's second byte is 7D, so the pairs
    # never overlap and four C-level replaces undo them; 7D 5D goes last so its 7D is final
    # (the others make no 7D, so their order is free). 7D 33 goes first, and alone when it
    # accounts for every 7D: an XBee's 64-bit address (00 13 A2 ..) puts one in every packet
    # it sends, often the only one. Each pair replaced removes one byte.
    size = len(data)
    out = data.replace(b"\x7d\x33", b"\x13")
    if size - len(out) != escapes:
        out = (out.replace(b"\x7d\x5e", b"\x7e").replace(b"\x7d\x31", b"\x11")
               .replace(b"\x7d\x5d", b"\x7d"))
    if size - len(out) == escapes:
        return bytes(out), size
    parts = bytes(data).split(b"\x7d")  # some escape is bad: find the valid prefix
    out = bytearray(parts[0])
    used = len(parts[0])
    for part in parts[1:]:
        if not part or (part[0] ^ 0x20) not in ESCAPED_BYTES:
            return bytes(out), used
        out.append(part[0] ^ 0x20)
        out += part[1:]
        used += 1 + len(part)
    return bytes(out), used


def unescape(data: bytes) -> bytes:
    """Inverse of :func:`escape`. Raises ValueError on a dangling or invalid escape."""
    out, used = unescape_partial(data)
    if used != len(data):
        raise ValueError(f"bad escape at byte {used}")
    return out


class _Escaped(Adapter):
    """API mode 2: the escaped image of an API mode 1 frame minus its start byte."""

    def _decode(self, obj, context, path):
        return ApiFrameBody.parse(unescape(obj))

    def _encode(self, obj, context, path):
        return escape(ApiFrameBody.build(obj))


ApiFrameBody = Struct(
    "frame" / RawCopy(Prefixed(Int16ub, FrameData)),
    "checksum" / Checksum(Int8ub, lambda raw: checksum(raw[2:]), this.frame.data),
)

#: One API mode 2 (escaped) frame.
ApiFrameEscaped = Struct(
    "start" / Const(bytes([START])),
    "escaped" / _Escaped(GreedyBytes),
)


def frame_data(frame_type: int, **fields) -> bytes:
    """Frame data (type + fields) for a declared type, or raw ``body=`` bytes."""
    return FrameData.build({"type": frame_type, "body": fields.get("body", fields)})


def wrap(data: bytes, escaped: bool) -> bytes:
    """A whole API frame around *data* (frame type + fields)."""
    if len(data) > MAX_FRAME_DATA or not data:
        raise ValueError(f"frame data of {len(data)} bytes cannot be framed")
    body = len(data).to_bytes(2, "big") + data + bytes((checksum(data),))
    return bytes((START,)) + (escape(body) if escaped else body)


def wrap_many(frame_data: bytes, lengths, escaped: bool) -> tuple[bytes, np.ndarray]:
    """:func:`wrap` of many frames at once (a coordinator's RF packets of a run): *frame_data*
    their data end to end, *lengths* bytes each; the frames end to end and their lengths.
    The same bytes as wrap's, in numpy calls over all of them, not a few calls per frame."""
    n = np.asarray(lengths, dtype=np.int64)
    if not len(n):
        return b"", n
    if n.min() < 1 or n.max() > MAX_FRAME_DATA:
        raise ValueError(f"frame data of {int(n.min() if n.min() < 1 else n.max())} bytes "
                         "cannot be framed")
    data = np.frombuffer(frame_data, dtype=np.uint8)
    first = np.cumsum(n) - n  # each frame's first data byte
    at = first + 4 * np.arange(len(n))  # each frame's start delimiter: 4 bytes more a frame
    out = np.empty(len(data) + 4 * len(n), dtype=np.uint8)
    out[at], out[at + 1], out[at + 2] = START, n >> 8, n & 0xFF
    out[np.arange(len(data)) + np.repeat(at + 3 - first, n)] = data
    out[at + 3 + n] = 0xFF - (np.add.reduceat(data, first, dtype=np.int64) & 0xFF)
    size = n + 4
    if escaped:  # each escaped byte after a start delimiter becomes 7D (b ^ 0x20)
        special = _SPECIAL[out]
        special[at] = False
        size += np.add.reduceat(special, at, dtype=np.int64)
        out = np.repeat(out, special + 1)
        pairs = np.flatnonzero(special) + np.arange(np.count_nonzero(special))
        out[pairs + 1] ^= 0x20
        out[pairs] = ESCAPE
    return out.tobytes(), size


def build(frame_type: int, escaped: bool = True, **fields) -> bytes:
    """A whole API frame of *frame_type* with *fields* (see the Structs above)."""
    return wrap(frame_data(frame_type, **fields), escaped)


def parse_frame_data(data: bytes):
    """Parse frame data (type + fields) into a construct Container ``{type, body}``."""
    return FrameData.parse(data)
