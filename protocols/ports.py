"""The lab computer's serial ports, each declared once for every side that uses it.

A :class:`Port` says everything the emulator, the host, ``navtwin decode`` and the audit
need of a port: its name (the link in the link directory, the recording's port, the host's
input), the wire format the host decodes it as and the format of its own frames
(protocols.formats), the device model behind it in the emulated lab (emulator.devices), its
rate unless a scenario or a command line says otherwise, and its places in the orders the
sides list and process ports in. Nothing else in navtwin names a port to decide something:
adding a port (a magnetometer board, a second vehicle's radio) is one declaration, its
format and its device model, registered here or in an installed package's ``navtwin.ports``
entry points (docs/architecture.md, "A port").

Orders. :func:`listed` is the lab's order: link directories, recordings and run summaries
list the ports in it (``order``). The host processes its inputs in ``host_order``: the
streams that carry the IMU samples before the ranges that wait for them, the coordinator's
first, so that of two copies of the IMU stream the radio's is the one the host keeps.

Several vehicles. A port belongs to a ``unit``: a vehicle (the SINS board's line), the
coordinator, the gateway, or the lab. A scenario with N vehicles has one port of a vehicle's
unit per vehicle, and one coordinator's or gateway's port per vehicle when it gives each
vehicle its own XBee or nanoLOC network (emulator.scenario). Vehicle 1's port has the
declared name; vehicle n's the name followed by n (``sins2``, ``xbee2``, ``nanoloc2``), so
every side resolves an instance to its declaration (:func:`get`, :func:`parse`) and a
one-vehicle lab's names never change.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from .plugins import Registry

DEFAULT_BAUD = 115200  # every port of the lab as shipped (the board, the gateway, BD = 7)


class PortError(ValueError):
    """A port declaration that cannot be registered; one line naming the fix."""


@dataclass(frozen=True)
class Port:
    """One serial port of the lab computer."""

    name: str
    format: str  # protocols.formats name the host decodes the port's bytes as
    device: str  # emulator.devices name of the device model behind it in the emulated lab
    doc: str
    baud: int = DEFAULT_BAUD  # default rate, 8N1
    order: int = 100  # place in the lab's listings (link directories, recordings, summaries)
    #: place in the host's processing order; None: the host does not read the port
    host_order: int | None = None
    carries_imu: bool = False  # its bytes carry the SINS sample stream (the host keeps one)
    #: format of the port's own frames, which the audit checks (default: ``format``); the
    #: coordinator's port carries SINS frames inside its XBee API frames
    frames: str = ""
    #: its bytes are XBee API frames: the decoders take the API mode the recording's port
    #: settings (``api_mode``) or the host's ``--api1`` say
    api_mode: bool = False
    #: its device reads what the host writes (the coordinator answers AT queries); the host
    #: writes its queries to it, and ``to_device`` line faults act on those bytes
    host_writes: bool = False
    #: what the port belongs to (module doc): "vehicle", "coordinator", "gateway" or "lab"
    unit: str = "lab"

    @property
    def reads_host(self) -> bool:
        """Whether the lab computer's host reads the port."""
        return self.host_order is not None

    @property
    def frame_format(self) -> str:
        return self.frames or self.format


def _check(name: str, port) -> None:
    if not isinstance(port, Port):
        raise PortError(f"port {name!r} is a {type(port).__name__}, not a "
                        "navtwin.protocols.ports.Port; declare it with Port(...)")
    if port.name != name:
        raise PortError(f"port declared as {port.name!r} is registered as {name!r}; use one name")


SINS = Port("sins", "sins", "board", "the SINS DSP board's frames over RS-232",
            order=0, host_order=1, carries_imu=True, unit="vehicle")
XBEE = Port("xbee", "xbee-sins", "coordinator",
            "the XBee coordinator's API frames (0x90 packets carry the SINS stream)",
            order=1, host_order=0, carries_imu=True, frames="xbee", api_mode=True,
            host_writes=True, unit="coordinator")
NANOLOC = Port("nanoloc", "nanoloc", "gateway", "the nanoLOC gateway's range reports",
               order=2, host_order=2, unit="gateway")

#: every port: the lab's three, then those registered in process, then installed packages'
PORTS: Registry[Port] = Registry("navtwin.ports", "port",
                                 {p.name: p for p in (SINS, XBEE, NANOLOC)},
                                 check=_check, error=PortError)


def escaped(settings) -> bool:
    """Whether a port's settings (its table in a scenario's or a recording's ``ports``) say
    XBee API mode 2, escaped: the mode when they name none (a port without an API mode
    ignores it)."""
    return settings.get("api_mode", 2) == 2


def listed() -> tuple[Port, ...]:
    """Every port, in the lab's order."""
    return tuple(sorted((p for _, p in PORTS.items()), key=lambda p: p.order))


def names() -> tuple[str, ...]:
    """Every port's name, in the lab's order."""
    return tuple(p.name for p in listed())


def host_inputs() -> tuple[str, ...]:
    """The ports the host reads, in its processing order."""
    return tuple(p.name for p in sorted((p for p in listed() if p.reads_host),
                                        key=lambda p: p.host_order))


def instance(name: str, n: int) -> str:
    """The name of vehicle *n*'s port of declaration *name* (module doc): ``sins``, ``sins2``."""
    return name if n == 1 else f"{name}{n}"


_NUMBERED = re.compile(r"(.+?)([1-9][0-9]*)")


def parse(name: str) -> tuple[str, int]:
    """(declaration, vehicle) of port instance *name*: ``sins2`` -> ("sins", 2); a declared
    name is itself, vehicle 1 (KeyError if *name* is neither)."""
    if name in PORTS:
        return name, 1
    m = _NUMBERED.fullmatch(name)
    if m is None or m[1] not in PORTS or int(m[2]) < 2:
        raise KeyError(name)
    return m[1], int(m[2])


def known(name: str) -> bool:
    """Whether *name* is a declared port or a vehicle's instance of one."""
    try:
        parse(name)
    except KeyError:
        return False
    return True


def get(name: str) -> Port:
    """The declaration of port *name*, or of the port it is an instance of (``sins2``: SINS);
    KeyError if none."""
    return PORTS.get(parse(name)[0])
