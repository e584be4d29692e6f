"""Device models: what stands behind each port of the emulated lab.

A port's declaration (protocols.ports) names its device model; :data:`DEVICES` maps the name
to a factory ``model(emulation, port) -> Device``, called once per run and port instance
(vehicle n's ``sins<n>``: the declaration under its instance's name) (installed packages add
theirs in the ``navtwin.devices`` entry-point group). The runner (emulator.runner) gives
every declared port a UART line and a PTY, and asks the port's device for everything else:

- ``line_device``: what the port's ``uart.Line`` times: an 8N1 wire at ``settings["baud"]``
  (:class:`Device`), or the coordinator, whose transmit buffer the line models;
- ``advance(until_ns)``: the device's own output, for a device the world (emulator.world)
  does not model: ``world.Event(t_ns, port, bytes)`` with ``t_ns < until_ns`` not given
  before, in time order (the lab's board and gateway are the world's: they give none);
- ``to_line(event)``: ``(t_ns, item)`` the line sends for one of the port's events;
- ``host(t_ns, data)``: what the device does with bytes the host wrote (its declaration
  says ``host_writes``): the items it sends back;
- ``settings``: the port's serial settings, recorded in the recording's meta and used for its
  PTY (``baud``; the coordinator's ``api_mode``); ``stats()``: extra run summary counters.
"""
from __future__ import annotations

from navtwin.protocols.plugins import Registry

from .uart import Wire


class DeviceError(ValueError):
    """A device model that cannot be registered; one line naming the fix."""


class Device:
    """A serial device whose output the world makes (the SINS board, the nanoLOC gateway)
    and that ignores what the host writes: its events go on an 8N1 wire unchanged."""

    def __init__(self, emulation, port) -> None:
        self.port = port
        # the scenario's settings of the port, or the declaration's rate for a port it
        # does not configure (a user's)
        self.settings = dict(emulation.scenario.ports.get(port.name, {"baud": port.baud}))
        self.line_device = Wire(self.settings["baud"])

    def advance(self, until_ns: int) -> list:
        return []

    def to_line(self, ev) -> tuple[int, object]:
        return ev.t_ns, ev.data

    def to_line_many(self, events: list) -> tuple[list, list]:
        """:meth:`to_line` of each of *events* (one port's, in order): their times and items."""
        got = [self.to_line(ev) for ev in events]
        return [t for t, _ in got], [item for _, item in got]

    def host(self, t_ns: int, data: bytes) -> list:
        return []

    def stats(self) -> dict:
        return {}


class CoordinatorDevice(Device):
    """The XBee coordinator on its port: it turns the RF packets it receives into 0x90 frames
    in its transmit buffer (the line), and answers what the host writes."""

    def __init__(self, emulation, port) -> None:
        super().__init__(emulation, port)
        self.coordinator = emulation.coordinators[port.name]
        self.channels = emulation.world.channels
        self.line_device = self.coordinator

    def to_line(self, ev) -> tuple[int, object]:
        out = self.coordinator.received(ev.t_ns, ev.data)
        return out.t_ns, out.item

    def to_line_many(self, events: list) -> tuple[list, list]:
        packets = [ev.data for ev in events]
        self.coordinator.received_all(packets)
        return [ev.t_ns for ev in events], packets

    def host(self, t_ns: int, data: bytes) -> list:
        return [(out.t_ns, out.item) for out in self.coordinator.host(t_ns, data)]

    def stats(self) -> dict:
        # RF packets its serial transmit buffer had no room for; with routers sharing its
        # channel, their packets their full queues dropped (emulator.channel)
        out = {"dropped_tx_buffer": self.coordinator.dropped_tx_buffer}
        if (channel := self.channels.get(self.port.name)) is not None:
            out["dropped_channel"] = channel.dropped
        return out


def _check(name: str, model) -> None:
    if not callable(model):
        raise DeviceError(f"device model {name!r} is a {type(model).__name__}, not a callable "
                          "model(emulation, port) -> Device; register a Device subclass")


#: device model name (a port declaration's ``device``) -> its factory
DEVICES: Registry = Registry("navtwin.devices", "device model",
                             {"board": Device, "gateway": Device, "coordinator": CoordinatorDevice},
                             check=_check, error=DeviceError)
