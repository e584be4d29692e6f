"""The ZigBee PRO network (NWK) and application support (APS) headers of an XBee ZB data
packet: what an XBee in transparent mode wraps around its RF data (the MAC payload of an
IEEE 802.15.4 data frame, protocols.ieee802154).

NWK header (ZigBee spec 3.3.1; no security, EE = 0; no IEEE addresses, no source route)::

    | frame control 2 | dst 2 | src 2 | radius 1 | seq 1 |

    frame control bits (little-endian, bit 0 least significant): 0-1 frame type (0 data)
    2-5 protocol version (2: ZigBee PRO)   6-7 discover route (1: enable)   8 multicast
    9 security   10 source route   11 dst IEEE address   12 src IEEE address   13-15 reserved

The radius starts at the sender's NH (maximum hops, XBee default 0x1E); the NWK sequence
number counts the sender's NWK frames.

APS header (ZigBee spec 2.2.5; unicast data, no APS acknowledgement asked)::

    | frame control 1 | dst endpoint 1 | cluster 2 | profile 2 | src endpoint 1 | counter 1 |

    frame control bits: 0-1 frame type (0 data)   2-3 delivery mode (0 unicast)
    4 ack format   5 security   6 ack request   7 extended header

An XBee in transparent mode (and a 0x10 transmit request) sends its data from endpoint 0xE8
to endpoint 0xE8, cluster 0x0011, in Digi's profile 0xC105 (Digi ZB manual, "Transparent
mode"); the APS counter counts the sender's APS frames.
"""
from __future__ import annotations

import struct

from construct import (BitsInteger, BitStruct, ByteSwapped, Const, Flag, GreedyBytes, Int8ul,
                       Int16ul, Padding, Struct)

from . import ieee802154

NWK_DATA, NWK_VERSION_PRO, DISCOVER_ROUTE_ENABLE = 0, 2, 1
APS_DATA, APS_UNICAST = 0, 0
COORDINATOR16 = 0x0000
DEFAULT_RADIUS = 0x1E  # the XBee's NH default
DIGI_ENDPOINT = 0xE8
DIGI_DATA_CLUSTER = 0x0011  # transparent serial data
DIGI_PROFILE = 0xC105

NwkFrameControl = ByteSwapped(BitStruct(
    Padding(3),
    "src_ieee" / Flag,
    "dst_ieee" / Flag,
    "source_route" / Flag,
    "security" / Flag,
    "multicast" / Flag,
    "discover_route" / BitsInteger(2),
    "version" / BitsInteger(4),
    "frame_type" / BitsInteger(2),
))
ApsFrameControl = BitStruct(
    "extended_header" / Flag,
    "ack_request" / Flag,
    "security" / Flag,
    "ack_format" / Flag,
    "delivery_mode" / BitsInteger(2),
    "frame_type" / BitsInteger(2),
)
NWK_FC = NwkFrameControl.build(dict(
    frame_type=NWK_DATA, version=NWK_VERSION_PRO, discover_route=DISCOVER_ROUTE_ENABLE,
    multicast=False, security=False, source_route=False, dst_ieee=False, src_ieee=False))
APS_FC = ApsFrameControl.build(dict(
    frame_type=APS_DATA, delivery_mode=APS_UNICAST, ack_format=False, security=False,
    ack_request=False, extended_header=False))

NwkHeader = Struct(
    "frame_control" / Const(NWK_FC),
    "dst" / Int16ul,
    "src" / Int16ul,
    "radius" / Int8ul,
    "seq" / Int8ul,
)
ApsHeader = Struct(
    "frame_control" / Const(APS_FC),
    "dst_endpoint" / Int8ul,
    "cluster" / Int16ul,
    "profile" / Int16ul,
    "src_endpoint" / Int8ul,
    "counter" / Int8ul,
)
#: the MAC payload of an XBee data packet
DataPacket = Struct("nwk" / NwkHeader, "aps" / ApsHeader, "data" / GreedyBytes)
NWK_HEADER_BYTES = NwkHeader.sizeof()  # 8
APS_HEADER_BYTES = ApsHeader.sizeof()  # 8

#: every byte an XBee data packet puts on the air besides its RF data
OVERHEAD_BYTES = (ieee802154.PHY_HEADER_BYTES + ieee802154.MAC_HEADER_BYTES + NWK_HEADER_BYTES
                  + APS_HEADER_BYTES + ieee802154.FCS_BYTES)

_NWK = struct.Struct("<HHBB")  # dst, src, radius, seq: NwkHeader after its control
_APS = struct.Struct("<BHHBB")  # dst endpoint, cluster, profile, src endpoint, counter


def data_packet(dst: int, src: int, radius: int, nwk_seq: int, aps_counter: int, data: bytes,
                *, src_endpoint: int = DIGI_ENDPOINT, dest_endpoint: int = DIGI_ENDPOINT,
                cluster: int = DIGI_DATA_CLUSTER, profile: int = DIGI_PROFILE) -> bytes:
    """The NWK and APS headers and *data*, by default from Digi's data endpoint to Digi's
    (an explicit 0x11 transmit request names its own; = ``DataPacket.build``)."""
    return (NWK_FC + _NWK.pack(dst, src, radius, nwk_seq & 0xFF)
            + APS_FC + _APS.pack(dest_endpoint, cluster, profile, src_endpoint,
                                 aps_counter & 0xFF)
            + data)
