"""IEEE 802.15.4 MAC frames as an XBee ZB radio puts them on the air (2.4 GHz O-QPSK PHY).

On the air a frame is a PPDU: ``preamble 4 | SFD 1 | PHR 1 | PSDU`` (the PHR holds the
PSDU's length); the PSDU is the MAC frame, its FCS last. A capture (pcap link type
``IEEE802_15_4_WITHFCS``, 195) holds the PSDU.

Data frame (unicast, as ZigBee PRO sends it: 2003 frame version, short addresses, one PAN)::

    | frame control 2 | seq 1 | dst PAN 2 | dst 2 | src 2 | MAC payload | FCS 2 |

ACK frame (sent by the receiver one turnaround, 12 symbols, after a data frame that asked)::

    | frame control 2 | seq 1 | FCS 2 |     seq = the acknowledged frame's

Multi-byte fields are little-endian; the frame control's bits (bit 0 = least significant)::

    0-2 frame type (1 data, 2 ack)   3 security   4 frame pending   5 ack request
    6 PAN ID compression (the source PAN is the destination's, not sent)   7-9 reserved
    10-11 dst address mode (2 short)   12-13 frame version (0: 2003)   14-15 src address mode

FCS: CRC-16/KERMIT over the MAC header and payload (ITU-T polynomial x^16 + x^12 + x^5 + 1,
bits reflected, init 0, no final xor), sent least significant byte first
(IEEE 802.15.4-2006 section 7.2.1.9; check value ``fcs(b"123456789") == 0x2189``).

The frame control words are built once from the declarations below; the per-frame builders
(:func:`data_frame`, :func:`ack_frame`) pack the fields that change, and equal the
construct builds (tests/protocols/test_ieee802154.py).
"""
from __future__ import annotations

import binascii
import struct

from construct import (BitsInteger, BitStruct, ByteSwapped, Const, Flag, GreedyBytes, Int8ul,
                       Int16ul, Padding, Struct)

PHY_HEADER_BYTES = 6  # preamble 4 + SFD 1 + PHR 1, before every PSDU on the air
BYTE_NS = 32_000  # 2 symbols of 16 us: 250 kbit/s
TURNAROUND_NS = 12 * 16_000  # aTurnaroundTime: a data frame's end to its ACK's first bit
FCS_BYTES = 2
FRAME_DATA, FRAME_ACK = 1, 2
ADDRESS_SHORT = 2
VERSION_2003 = 0

#: the 16 bits of the frame control, most significant first (ByteSwapped: it is little-endian)
FrameControl = ByteSwapped(BitStruct(
    "src_mode" / BitsInteger(2),
    "version" / BitsInteger(2),
    "dst_mode" / BitsInteger(2),
    Padding(3),
    "pan_id_compression" / Flag,
    "ack_request" / Flag,
    "frame_pending" / Flag,
    "security" / Flag,
    "frame_type" / BitsInteger(3),
))

_DATA_FC = dict(frame_type=FRAME_DATA, security=False, frame_pending=False, ack_request=True,
                pan_id_compression=True, dst_mode=ADDRESS_SHORT, version=VERSION_2003,
                src_mode=ADDRESS_SHORT)
_ACK_FC = dict(frame_type=FRAME_ACK, security=False, frame_pending=False, ack_request=False,
               pan_id_compression=False, dst_mode=0, version=VERSION_2003, src_mode=0)
DATA_FC = FrameControl.build(_DATA_FC)
ACK_FC = FrameControl.build(_ACK_FC)

#: the data frame's MAC header (unicast, short addresses, PAN ID compressed)
DataHeader = Struct(
    "frame_control" / Const(DATA_FC),
    "seq" / Int8ul,
    "dst_pan" / Int16ul,
    "dst" / Int16ul,
    "src" / Int16ul,
)
AckHeader = Struct(
    "frame_control" / Const(ACK_FC),
    "seq" / Int8ul,
)
MAC_HEADER_BYTES = DataHeader.sizeof()  # 9
ACK_PSDU_BYTES = AckHeader.sizeof() + FCS_BYTES  # 5
#: a data frame's end to its ACK's end: turnaround and the ACK's PPDU (544 us)
ACK_NS = TURNAROUND_NS + (PHY_HEADER_BYTES + ACK_PSDU_BYTES) * BYTE_NS

#: a whole data PSDU; ``fcs`` is checked by :func:`fcs` on the bytes before it
DataFrame = Struct("header" / DataHeader, "payload" / GreedyBytes)


#: each byte with its bits in reverse order
_REVERSED = bytes(int(f"{b:08b}"[::-1], 2) for b in range(256))


def fcs(data: bytes) -> int:
    """CRC-16/KERMIT of *data* (the 802.15.4 FCS: polynomial 0x1021, bits reflected, init 0).

    KERMIT is XMODEM (the same polynomial, unreflected, init 0: ``binascii.crc_hqx``) of the
    bit-reversed bytes, its 16-bit result bit-reversed; so the sum runs in C, about 13x a
    table lookup per byte in Python (every frame on the air carries one)."""
    crc = binascii.crc_hqx(data.translate(_REVERSED), 0)
    return _REVERSED[crc & 0xFF] << 8 | _REVERSED[crc >> 8]


def with_fcs(mpdu: bytes) -> bytes:
    """*mpdu* (MAC header and payload) with its FCS appended: the PSDU."""
    return mpdu + struct.pack("<H", fcs(mpdu))


_ADDRESSES = struct.Struct("<BHHH")  # seq, dst PAN, dst, src: DataHeader after its control


def data_frame(seq: int, pan: int, dst: int, src: int, payload: bytes) -> bytes:
    """The PSDU of a unicast data frame from short address *src* to *dst* on PAN *pan*,
    asking for an ACK (= ``DataFrame.build`` + FCS)."""
    return with_fcs(DATA_FC + _ADDRESSES.pack(seq & 0xFF, pan, dst, src) + payload)


def ack_frame(seq: int) -> bytes:
    """The PSDU of the ACK of the data frame with MAC sequence number *seq*."""
    return _ACKS[seq & 0xFF]


_ACKS = [with_fcs(ACK_FC + bytes((seq,))) for seq in range(256)]  # one per sequence number

