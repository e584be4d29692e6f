"""A lab's byte streams as a pcapng capture: one interface per port, each with the link type
its frames' dissector is registered for.

Link types. The lab's serial formats have no link type of their own, so they take the
user range (LINKTYPE_USER0..15, which tcpdump.org leaves to private use); the Lua
dissectors shipped with navtwin (``protocols/wireshark/``) register on the same numbers,
taken from :data:`LINKTYPES`, written once here. XBee API frames come in two framings
(API mode 2 escapes 0x7E 0x7D 0x11 0x13; mode 1 does not), so each has its own. A port
whose format has no dissector is captured as :data:`UNDISSECTED` (raw bytes).

Directions. A packet's epb_flags say which way it went, seen from the lab computer:
``to_host`` bytes (a device's writes) are inbound, ``to_device`` ones (what the host wrote to
the coordinator) outbound. Both directions of a port share its interface.
"""
from __future__ import annotations

from typing import BinaryIO

from . import ports
from .pcapng import INBOUND, LINKTYPE_USER0, OUTBOUND, Writer

#: (frame format, XBee API mode 2) -> link type; the Lua dissectors read the same table
LINKTYPES = {
    ("sins", False): LINKTYPE_USER0,
    ("nanoloc", False): LINKTYPE_USER0 + 1,
    ("xbee", True): LINKTYPE_USER0 + 2,
    ("xbee", False): LINKTYPE_USER0 + 3,
}
UNDISSECTED = LINKTYPE_USER0 + 15
DIRECTION = {"to_host": INBOUND, "to_device": OUTBOUND}


def linktype(port: str, settings: dict) -> int:
    """The link type of port *port* with its *settings* (a recording's or scenario's
    ``ports`` table): its frames' format, in its API mode."""
    declared = ports.get(port)
    key = (declared.frame_format, declared.api_mode and ports.escaped(settings))
    return LINKTYPES.get(key, UNDISSECTED)


class Capture:
    """A pcapng capture of a lab's ports on *out*; interfaces are declared as ports first
    send packets, in that order."""

    def __init__(self, out: BinaryIO, port_settings: dict[str, dict]) -> None:
        self.writer = Writer(out)
        self.settings = port_settings
        self.interfaces: dict[str, int] = {}

    def interface(self, name: str, linktype_: int, description: str = "") -> int:
        """Declare a stream that is not a port (the air): its interface id."""
        self.interfaces[name] = self.writer.interface(name, linktype_, description)
        return self.interfaces[name]

    def port(self, name: str) -> int:
        """Port *name*'s interface, declared when first used."""
        if name not in self.interfaces:
            self.interface(name, linktype(name, self.settings.get(name, {})),
                           ports.get(name).doc)
        return self.interfaces[name]

    def chunk(self, port: str, t_ns: int, data: bytes, direction: str = "to_host",
              comment: str = "") -> None:
        """One chunk of *port* at *t_ns* going *direction* (``to_host``/``to_device``)."""
        self.writer.packet(self.port(port), t_ns, data, direction=DIRECTION[direction],
                           comment=comment)

    def flush(self) -> None:
        self.writer.flush()
