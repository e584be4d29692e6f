"""The lab computer's serial ports, declared once for both sides.

Each port has a name (the link in the link directory, the recording's port, the host's
input), the wire format it carries (protocols.decode's format names) and the rate it runs
at unless a scenario or a command line says otherwise. :data:`PORTS` is the lab's order:
link directories, recordings and run summaries list the ports in it. A side that needs
another order for a reason of its own (the world's order of simultaneous events, the
host's processing order of equal stamps) writes it with these names.
"""
from __future__ import annotations

from typing import NamedTuple

DEFAULT_BAUD = 115200  # every port of the lab as shipped (the board, the gateway, BD = 7)


class Port(NamedTuple):
    name: str
    format: str  # protocols.decode format of what the port carries
    baud: int  # default rate, 8N1
    doc: str


SINS = Port("sins", "sins", DEFAULT_BAUD, "the SINS DSP board's frames over RS-232")
XBEE = Port("xbee", "xbee", DEFAULT_BAUD, "the XBee coordinator's API frames")
NANOLOC = Port("nanoloc", "nanoloc", DEFAULT_BAUD, "the nanoLOC gateway's range reports")
PORTS = (SINS, XBEE, NANOLOC)
NAMES = tuple(p.name for p in PORTS)
BY_NAME = {p.name: p for p in PORTS}
