"""pcapng, the capture format Wireshark and tshark read: a writer, as the spec's blocks.

The blocks navtwin writes (IETF draft-ietf-opsawg-pcapng, little-endian, every block and
option padded to 32 bits)::

    Section Header Block    0x0A0D0D0A  byte-order magic 0x1A2B3C4D, version 1.0,
                                        section length -1 (unknown: written as a stream)
    Interface Description   0x00000001  link type, snap length 0 (no limit),
                                        if_name, if_description, if_tsresol = 9 (ns)
    Enhanced Packet Block   0x00000006  interface id, timestamp (ns, high and low 32 bits),
                                        captured and original length, data,
                                        epb_flags (direction), opt_comment

One interface per byte stream: each of the lab's ports, the radio's air. A port is a stream,
not packets: a packet is one chunk as the recording or the tap has it (one device write or
one host read), so a frame may span packets and a packet may hold several frames.

The writer streams (an extcap writes into Wireshark's FIFO as the lab runs): blocks go to
the file as they are made, and ``flush`` pushes them out.
"""
from __future__ import annotations

import struct
from typing import BinaryIO

SHB, IDB, EPB = 0x0A0D0D0A, 0x00000001, 0x00000006
BYTE_ORDER_MAGIC = 0x1A2B3C4D
#: link types (tcpdump.org/linktypes.html): the user range for our serial formats, whose
#: dissectors we ship; 802.15.4 with its FCS for the air, dissected by Wireshark itself
LINKTYPE_USER0 = 147
LINKTYPE_IEEE802_15_4_WITHFCS = 195
OPT_END, OPT_COMMENT = 0, 1
SHB_HARDWARE, SHB_OS, SHB_USERAPPL = 2, 3, 4
IF_NAME, IF_DESCRIPTION, IF_TSRESOL = 2, 3, 9
EPB_FLAGS = 2
#: epb_flags bits 0-1: the direction of a packet, seen from the lab computer's port
INBOUND, OUTBOUND = 0b01, 0b10


def _pad(data: bytes) -> bytes:
    return data + b"\0" * (-len(data) % 4)


def _options(options: list[tuple[int, bytes]]) -> bytes:
    if not options:
        return b""
    body = b"".join(struct.pack("<HH", code, len(value)) + _pad(value)
                    for code, value in options)
    return body + struct.pack("<HH", OPT_END, 0)


def _block(kind: int, body: bytes) -> bytes:
    size = 12 + len(body)  # type, length, body, length again
    return struct.pack("<II", kind, size) + body + struct.pack("<I", size)


class Writer:
    """A pcapng stream on *out* (a binary file): the section header now, then interfaces
    and packets in the order they are added."""

    def __init__(self, out: BinaryIO, *, application: str = "navtwin") -> None:
        self.out = out
        self.interfaces: list[str] = []
        body = struct.pack("<IHHq", BYTE_ORDER_MAGIC, 1, 0, -1)
        self.out.write(_block(SHB, body + _options([(SHB_USERAPPL, application.encode())])))

    def interface(self, name: str, linktype: int, description: str = "") -> int:
        """Declare an interface: its id, which :meth:`packet` takes."""
        options = [(IF_NAME, name.encode()), (IF_TSRESOL, b"\x09")]
        if description:
            options.append((IF_DESCRIPTION, description.encode()))
        self.out.write(_block(IDB, struct.pack("<HHI", linktype, 0, 0) + _options(options)))
        self.interfaces.append(name)
        return len(self.interfaces) - 1

    def packet(self, interface: int, t_ns: int, data: bytes, *, direction: int = 0,
               comment: str = "") -> None:
        """One packet on *interface* at *t_ns* (ns since 1970-01-01; a lab's device time
        counts from 0); *direction* :data:`INBOUND` or :data:`OUTBOUND` (0: not said)."""
        if not 0 <= interface < len(self.interfaces):
            raise ValueError(f"interface: {interface} is not declared; declare it with "
                             "Writer.interface first")
        options = []
        if direction:
            options.append((EPB_FLAGS, struct.pack("<I", direction)))
        if comment:
            options.append((OPT_COMMENT, comment.encode()))
        head = struct.pack("<IIIII", interface, (t_ns >> 32) & 0xFFFFFFFF, t_ns & 0xFFFFFFFF,
                           len(data), len(data))
        self.out.write(_block(EPB, head + _pad(bytes(data)) + _options(options)))

    def flush(self) -> None:
        self.out.flush()
