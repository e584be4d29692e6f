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

A recording as a capture (:func:`write_recording`, ``navtwin pcap``): every chunk of every
port is one packet, in time order across the ports, on the clock asked for (device time by
default; a host recording has wall time only); the other clock and the fault ledger's entries
that touch the chunk's bytes go in the packet's comment. A recording's port whose settings
say ``{"of": PORT}`` (a host recording's ``xbee.tx``) is PORT's ``to_device`` direction.
A stream of the recording that is not a port (an emulator recording's ``air``: the XBee
hop's IEEE 802.15.4 frames, protocols.ieee802154) is an interface of its own with the
stream's link type, so Wireshark's own wpan, ZigBee NWK and APS dissectors show the radio
between the two wires.
"""
from __future__ import annotations

import bisect
import heapq
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Iterator

from . import ports
from .pcapng import INBOUND, LINKTYPE_USER0, OUTBOUND, Writer
from .recording import Chunk, Recording

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
    try:
        declared = ports.get(port)
    except KeyError:  # a port this navtwin does not know: its bytes, undissected
        return UNDISSECTED
    key = (declared.frame_format, declared.api_mode and ports.escaped(settings))
    return LINKTYPES.get(key, UNDISSECTED)


def _doc(port: str) -> str:
    try:
        return ports.get(port).doc
    except KeyError:
        return ""


def dissectors_path() -> Path:
    """The Lua file of navtwin's Wireshark dissectors (shipped in the package):
    ``tshark -X lua_script:PATH``, or copy it to ~/.local/lib/wireshark/plugins/."""
    return Path(__file__).resolve().parent / "wireshark" / "navtwin.lua"


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
                           _doc(name))
        return self.interfaces[name]

    def chunk(self, port: str, t_ns: int, data: bytes, direction: str = "to_host",
              comment: str = "") -> None:
        """One chunk of *port* at *t_ns* going *direction* (``to_host``/``to_device``)."""
        self.writer.packet(self.port(port), t_ns, data, direction=DIRECTION[direction],
                           comment=comment)

    def stream(self, name: str, linktype_: int, doc: str, t_ns: int, data: bytes,
               comment: str = "") -> None:
        """One packet of a stream that is not a port (the air) at *t_ns*, on an interface of
        its own with the stream's link type, declared with its first packet; a stream has no
        direction seen from the lab computer."""
        if name not in self.interfaces:
            self.interface(name, linktype_, doc)
        self.writer.packet(self.interfaces[name], t_ns, data, comment=comment)

    def flush(self) -> None:
        self.writer.flush()


CLOCKS = {"device": "t_device_ns", "wall": "t_wall_ns"}


class CaptureError(ValueError):
    """A recording that cannot be written as asked: one line naming the setting and the fix."""


@dataclass
class Written:
    """What :func:`write_recording` wrote: the clock of the timestamps, and per interface
    its packets and bytes, in the order the interfaces were declared."""
    clock: str
    packets: dict[str, int] = field(default_factory=dict)
    bytes: dict[str, int] = field(default_factory=dict)

    def summary(self) -> str:
        per = ", ".join(f"{name} {n} packets ({self.bytes[name]} bytes)"
                        for name, n in self.packets.items())
        return f"{sum(self.packets.values())} packets, {self.clock} time: {per or 'no packets'}"


def clock_for(recording: Recording, clock: str) -> str:
    """The clock the timestamps of *recording* come from: *clock* (``device`` or ``wall``),
    or ``wall`` for ``device`` in a recording without device times (a host's)."""
    if clock not in CLOCKS:
        raise CaptureError(f"clock: {clock!r} is not one of {', '.join(CLOCKS)}")
    firsts = [c for c in (next(recording.chunks(p), None) for p in recording.ports) if c]
    if clock == "device" and firsts and all(c.t_device_ns is None for c in firsts):
        return "wall"  # a host recording: arrival times are all it has
    if firsts and all(getattr(c, CLOCKS[clock]) is None for c in firsts):
        raise CaptureError(f"clock: the recording has no {clock} times (an emulator run at "
                           f"full speed has device times only); use the device clock")
    return clock


class _Faults:
    """The fault ledger's entries by the port (and direction) whose bytes they touch: the
    entries that touch a chunk, found by bisection on their starts."""

    def __init__(self, entries: list[dict]) -> None:
        self.by_stream: dict[tuple, tuple[list[int], list[dict], int]] = {}
        grouped: dict[tuple, list[dict]] = {}
        for e in entries:
            if e["port"] is not None and e["start"] is not None:
                grouped.setdefault((e["port"], e["direction"] or "to_host"), []).append(e)
        for key, es in grouped.items():
            es.sort(key=lambda e: e["start"])
            self.by_stream[key] = ([e["start"] for e in es], es,
                                   max(e["end"] - e["start"] for e in es))

    def touching(self, port: str, direction: str, start: int, end: int) -> list[dict]:
        """The entries whose bytes [start, end) of the stream overlap the chunk's [start,
        end); an entry of removed bytes (start == end) touches the chunk it is in."""
        starts, entries, longest = self.by_stream.get((port, direction), ((), (), 0))
        hi = bisect.bisect_left(starts, end)
        lo = bisect.bisect_left(starts, start - longest, 0, hi)
        return [e for e in entries[lo:hi] if max(e["end"], e["start"] + 1) > start]


def _fault_note(e: dict) -> str:
    span = f"bytes {e['start']}..{e['end']}" if e["end"] > e["start"] else f"at byte {e['start']}"
    return f"fault {e['kind']} #{e['fault']} {span}"


def _port_packets(recording: Recording, clock: str) -> Iterator[tuple[int, Chunk]]:
    """Every chunk of every port in time order on *clock* (ties: port name order)."""
    attr = CLOCKS[clock]
    for chunk in recording.merged(clock=attr):
        yield getattr(chunk, attr) or 0, chunk


def _stream_packets(recording: Recording, name: str, rank: int,
                    clock: str) -> Iterator[tuple[int, int, Chunk]]:
    """The chunks of stream *name* (not a port: the air) on *clock*, ranked after the ports
    and the streams before it at equal times."""
    attr = CLOCKS[clock]
    for chunk in recording.chunks(name):
        yield getattr(chunk, attr) or 0, rank, chunk


def write_recording(recording: Recording, out: BinaryIO, *, clock: str = "device") -> Written:
    """Write *recording* to *out* as a pcapng capture (the module docstring): one interface
    per port and per stream that is not a port (the air, with its own link type), a packet
    per chunk in time order, timestamps on *clock* (``device`` or ``wall``; ``device`` falls
    back to wall in a recording without device times). What was written."""
    used = clock_for(recording, clock)
    other = {"device": "wall", "wall": "device"}[used]
    settings = recording.meta["ports"]
    faults = _Faults(recording.faults())  # validated before a byte is written
    capture = Capture(out, {p: s for p, s in settings.items() if "of" not in s})
    written = Written(used)
    ports_ = ((t, 0, chunk) for t, chunk in _port_packets(recording, used))
    streams = [_stream_packets(recording, name, rank, used)
               for rank, name in enumerate(recording.streams, 1)]
    for t, rank, chunk in heapq.merge(ports_, *streams, key=lambda x: x[:2]):
        other_t = getattr(chunk, CLOCKS[other])
        notes = [f"{CLOCKS[other]}={other_t}"] if other_t is not None else []
        port = chunk.port
        if rank:
            stream = recording.streams[port]
            capture.stream(port, stream.linktype, stream.doc, t, chunk.data, "; ".join(notes))
        else:
            direction = "to_host"
            if "of" in settings[port]:
                port, direction = settings[port]["of"], "to_device"
            notes += [_fault_note(e) for e in faults.touching(
                port, direction, chunk.offset, chunk.offset + len(chunk.data))]
            capture.chunk(port, t, chunk.data, direction, "; ".join(notes))
        written.packets[port] = written.packets.get(port, 0) + 1
        written.bytes[port] = written.bytes.get(port, 0) + len(chunk.data)
    capture.flush()
    return written
