"""ZigBee Device Objects (endpoint 0, profile 0) that an emulated XBee answers over the air.

Every ZigBee node's stack serves the mandatory ZDO requests itself, whatever its API
firmware, so a 0x11 Explicit Addressing frame to a router's endpoint 0 gets the router's
answer back as a 0x91 (when the coordinator's AO has bit 0 set). digi-xbee asks for the node
descriptor (cluster 0x0002) to learn a ZB node's role, because ZB 2x7x has no CE (devices.py
``_determine_role``, models/zdo.py ``NodeDescriptorReader``).

Payloads are little-endian (ZigBee specification 05-3474, sect. 2.4.3.1 and 2.4.4.2): a
request is ``transaction, NWKAddrOfInterest``; the answer, on the request's cluster with bit
15 set, is ``transaction, status, NWKAddrOfInterest, descriptor``. A request for another
node's address answers status DEVICE_NOT_FOUND with no descriptor; a request too short to
hold its address, or for a service not emulated, gets no answer.
"""
from __future__ import annotations

from typing import Callable

from navtwin.protocols.xbee import DIGI_MANUFACTURER

RESPONSE = 0x8000  # a ZDO answer's cluster: the request's with bit 15 set
SUCCESS = 0x00
DEVICE_NOT_FOUND = 0x81
NODE_DESC_REQ = 0x0002

FREQ_2400_MHZ = 0x40  # byte 1: frequency band bit 3 (of bits 3-7), APS flags 0
# MAC capabilities of a mains-powered router (the only remote node emulated): full-function
# device, mains, receiver on when idle, allocate address (bits 1, 2, 3, 7)
MAC_CAPABILITIES = 0x8E
# Buffer and transfer sizes of the EM250's EmberZNet stack: not in Digi's manual (uncertain;
# digi-xbee reads them but only the logical type decides the role).
MAX_BUFFER = 0x52
MAX_TRANSFER = 0x0052


def node_descriptor(logical_type: int) -> bytes:
    """The 13-byte node descriptor of an S2B: logical type 0 coordinator, 1 router, 2 end
    device; no complex or user descriptor, no server roles."""
    return (bytes((logical_type, FREQ_2400_MHZ, MAC_CAPABILITIES))
            + DIGI_MANUFACTURER.to_bytes(2, "little") + bytes((MAX_BUFFER,))
            + MAX_TRANSFER.to_bytes(2, "little") + (0).to_bytes(2, "little")  # server mask
            + MAX_TRANSFER.to_bytes(2, "little") + bytes((0,)))  # descriptor capabilities


#: Request cluster -> the descriptor a node of a logical type answers with.
SERVICES: dict[int, Callable[[int], bytes]] = {NODE_DESC_REQ: node_descriptor}


def answer(cluster: int, data: bytes, addr16: int,
           logical_type: int) -> tuple[int, bytes] | None:
    """(answer cluster, payload) of the node at *addr16* to the ZDO request *data* on
    *cluster*, or None when it does not answer."""
    service = SERVICES.get(cluster)
    if service is None or len(data) < 3:
        return None
    transaction, wanted = data[0], int.from_bytes(data[1:3], "little")
    head = bytes((transaction,))
    if wanted != addr16:
        return cluster | RESPONSE, head + bytes((DEVICE_NOT_FOUND,)) + data[1:3]
    return (cluster | RESPONSE,
            head + bytes((SUCCESS,)) + data[1:3] + service(logical_type))
