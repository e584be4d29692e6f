"""The lab computer's XBee-PRO S2B: a ZB coordinator in API mode 1 or 2.

It turns the RF packets its radio receives into 0x90 Receive Packet frames (0x91 when AO
bit 0 is set) and answers the host's API frames as XBee ZB firmware 21A7 does
(``shared/reference/xbee-api-facts.md``):

==========  ===========================================================================
0x08        AT command: a query answers 0x88 with the value; a set applies it (and every
            value queued by 0x09) and answers 0x88 OK; unknown command -> status 2,
            bad value -> status 3, set of a read-only register -> status 1
0x09        queued AT command: a query answers like 0x08; a set is queued until AC or
            the next 0x08 set
0x10 0x11   transmit request -> 0x8B after the link's delivery time: 0x00 delivered,
            0x21 network ACK failure (retries exhausted), 0x74 payload over NP,
            0x24 address not found (unknown 64-bit address), 0x25 route not found
            (unknown 16-bit address), 0x23 self-addressed; broadcasts always 0x00.
            A 0x11 to the router's ZDO endpoint (0, profile 0) is also answered by the
            router's stack (emulator.zdo): a 0x91 from it when AO bit 0 is set.
            A unicast to the router goes on the air (``air``, emulator.radio.Sender):
            each attempt a data frame from MY to the router, and the router's ACK
0x17        remote AT command to the router -> 0x97 with the router's register value,
            status 4 when the request or the answer is lost or the address is unknown
==========  ===========================================================================

Frame ID 0 suppresses the 0x88 / 0x8B / 0x97 answer, not the action. Every answer leaves
``response_delay_ns`` (3 ms) or more after the request arrived: a real module takes that
long, and digi-xbee 1.5.0 loses answers that come before it waits (race in
``SyncRequestSender``).

Executable commands: AC (apply queued values), WR (remember the values a reset restores),
RE (back to the scenario's values), FR (OK, then after ``RESET_NS`` modem status 0x01 watchdog reset
and, ``START_NS`` later, 0x06 coordinator started; values not written with WR are lost,
and RF packets arriving during the reset are not reported), ND (one 0x88 per remote node,
i.e. the router, each after a random delay within NT x 100 ms, drawn from the
coordinator's own generator; ND with a parameter asks for that NI only. There is no OK
before and no empty 0x88 after the node answers: ZB firmware sends neither in API mode,
and python-xbee's ND parser loops forever on an empty one, so digi-xbee ends a ZB
discovery on its NT timeout, as with real hardware).

Role question: digi-xbee's ``open()`` reads CE after HV, VR, SH, SL, NI, MY. A 2x7x module
answers CE with status 2, which costs digi-xbee an 8 s ZDO fallback; this coordinator
answers CE = 1, so ``open()`` reports ``Role.COORDINATOR`` at once. The router (reached by
0x17) answers CE with status 2, as 22A7 firmware does; digi-xbee then asks the router for its
ZDO node descriptor, which the router answers with logical type 1 (``Role.ROUTER``).

Both modules answer the S2B's AT registers (``PARAMS``: the I/O pins D0-D7 and P0-P2, IR,
IC and the rest XCTU reads) with the factory defaults of Digi's ZB manual.

Changes of AP (escaping) and BD (UART rate) take effect after the OK answer has gone out
(immediately when the request had frame ID 0). AP 0 (transparent) is not emulated and is
refused with status 3. Sets on the router are stored and answered but do not change the
device model (its packetisation keeps the scenario's RO and NP).

Power-up: modem status 0x00 (hardware reset) at t = 0, then 0x06 (coordinator started).

Serial transmit buffer: an RF packet whose frame does not fit in the ``SERIAL_TX_BUFFER``
bytes still queued for the UART when it arrives is dropped whole and counted
(``dropped_tx_buffer``), as the firmware does when the host line is slower than the RF
data (xbee-api-facts.md section 5). Answers to the host are never dropped: they are small
and one per request, so the host's own requests bound them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, NamedTuple

import numpy as np

from navtwin.protocols import xbee
from navtwin.protocols.stream import Frame, XBeeDecoder
from navtwin.protocols.xbee import AtStatus, DeliveryStatus, FrameType, ModemStatus
from navtwin.protocols.zigbee import DEFAULT_RADIUS

from . import zdo
from .radio import Sender

MS = 1_000_000
RESPONSE_DELAY_NS = 3 * MS
RESET_NS = 100 * MS  # FR: software reset until modem status 0x01
START_NS = 400 * MS  # then until the coordinator has re-formed its network (0x06)
POWER_UP_START_NS = 5 * MS
ADDRESS_TIMEOUT_NS = 1_600 * MS  # unicast timeout (50 x NH + 100 ms, NH = 0x1E)
BROADCAST_PAYLOAD_EXTRA = 8  # a ZB broadcast carries 8 bytes more than NP
DIGI_PROFILE = 0xC105
DIGI_DATA = (0xE8, 0xE8, 0x0011, DIGI_PROFILE)  # endpoints, cluster, profile of 0x91 data
ZDO_RX_OPTIONS = 0x01  # a ZDO answer is an acknowledged unicast
# Serial transmit buffer. S2B's size is undocumented (the S1's 100 B does not apply): 512 B
# holds two maximal escaped 0x90 frames or ten SINS packets, and drains in 0.53 s at 9600.
SERIAL_TX_BUFFER = 512
TEXT = 0  # Param.size of a text register


@dataclass(frozen=True)
class Param:
    """An AT register: answer width in bytes (TEXT for NI), factory default (None: set by the
    module's identity, or absent), writable, valid values."""

    size: int
    default: Any = None
    writable: bool = True
    valid: Callable[[Any], bool] = lambda v: True


def _range(lo: int, hi: int) -> Callable[[int], bool]:
    return lambda v: lo <= v <= hi


def _one_of(*values: int) -> Callable[[int], bool]:
    return lambda v: v in values


def _read_only(size: int, default: Any = None) -> Param:
    return Param(size, default, writable=False)


def _pin(default: int, *functions: int) -> Param:
    """A pin configuration register (D0-D7, P0-P2): 0 disabled/unmonitored input, 3 digital
    input, 4/5 digital output low/high, plus the pin's own *functions* (1 its alternate
    function, 2 analog input, 6/7 RS-485 enable)."""
    return Param(1, default, valid=_one_of(0, 3, 4, 5, *functions))


#: The registers of an XBee-PRO S2B with ZB 2x7x firmware that this emulation answers, with
#: the factory defaults of Digi's "XBee/XBee-PRO ZB RF Modules" manual (90000976, rev. J,
#: 2012, "XBee Command Reference Tables"; I/O table p. 134 of the 2011 edition for IR, IC,
#: P0-P2) and xbee-api-facts.md sect. 2. Local (0x08/0x09) and remote (0x17) AT use the same
#: table, so the coordinator and the router answer alike. A name that is not here, or has no
#: default and no identity value (CE on the router, as 2x7x has none), is "invalid command".
PARAMS: dict[str, Param] = {
    # identity and network state: read-only
    "SH": _read_only(4), "SL": _read_only(4), "HV": _read_only(2), "VR": _read_only(2),
    "MY": _read_only(2, 0xFFFE), "MP": _read_only(2, 0xFFFE), "OP": _read_only(8, 0),
    "OI": _read_only(2, 0), "CH": _read_only(1, 0x0C), "AI": _read_only(1, 0x00),
    "NP": _read_only(2, 0x54), "CE": _read_only(1),
    "DB": _read_only(1, 0x28),  # fixed -40 dBm: the link model has no RSSI
    # addressing and networking
    "NI": Param(TEXT, b" ", valid=lambda v: len(v) <= 20 and all(0x20 <= b < 0x7F for b in v)),
    "ID": Param(8, 0), "DH": Param(4, 0), "DL": Param(4, 0), "DD": Param(4, 0x30000),
    "NT": Param(1, 0x3C, valid=_range(0x20, 0xFF)), "NO": Param(1, 0, valid=_range(0, 7)),
    "SC": Param(2, 0x1FFE, valid=_range(1, 0x7FFF)), "SD": Param(1, 3, valid=_range(0, 7)),
    "ZS": Param(1, 0, valid=_range(0, 2)), "NJ": Param(1, 0xFF), "NH": Param(1, DEFAULT_RADIUS),
    "BH": Param(1, 0, valid=_range(0, 0x1E)), "AR": Param(1, 0xFF),
    "JV": Param(1, 0, valid=_range(0, 1)), "NW": Param(2, 0, valid=_range(0, 0x64FF)),
    "JN": Param(1, 0, valid=_range(0, 1)),
    # RF, security, sleep
    "PL": Param(1, 4, valid=_range(0, 4)), "PM": Param(1, 1, valid=_range(0, 1)),
    "EE": Param(1, 0, valid=_range(0, 1)), "SM": Param(1, 0, valid=_one_of(0)),
    "SN": Param(2, 1, valid=_range(1, 0xFFFF)), "SP": Param(2, 0x20, valid=_range(0x20, 0xAF0)),
    "ST": Param(2, 0x1388, valid=_range(1, 0xFFFE)),
    # serial interfacing; AP and BD come from the scenario (the factory's are 1 and 3)
    "AP": Param(1, 2, valid=_one_of(1, 2)), "AO": Param(1, 0, valid=_one_of(0, 1, 3)),
    "BD": Param(4, 7, valid=lambda v: v <= 7 or 0x80 <= v <= 0xE1000),
    "NB": Param(1, 0, valid=_range(0, 3)), "SB": Param(1, 0, valid=_range(0, 1)),
    "RO": Param(1, 3),
    "D7": _pin(1, 1, 6, 7),  # CTS flow control
    "D6": _pin(0, 1),  # RTS flow control
    # I/O
    "D0": _pin(1, 1, 2),  # commissioning button
    "D1": _pin(0, 2), "D2": _pin(0, 2), "D3": _pin(0, 2), "D4": _pin(0),
    "D5": _pin(1, 1),  # associated indicator LED
    "P0": _pin(1, 1),  # RSSI PWM output
    "P1": _pin(0), "P2": _pin(0),
    "IR": Param(2, 0, valid=lambda v: v == 0 or 0x32 <= v <= 0xFFFF),  # sample period, ms
    "IC": Param(2, 0), "LT": Param(1, 0, valid=lambda v: v == 0 or 0x0A <= v <= 0xFF),
    "RP": Param(1, 0x28), "V+": Param(2, 0),
}
EXECUTE = ("AC", "WR", "RE", "FR")  # and ND, which answers differently

#: Register values of a fresh module (where the identity does not set them).
DEFAULTS: dict[str, Any] = {k: p.default for k, p in PARAMS.items() if p.default is not None}


class Registers:
    """One module's AT registers: applied values, the 0x09 queue, and what WR saved."""

    def __init__(self, values: dict[str, Any]) -> None:
        self.params = PARAMS
        self.factory = {k: v for k, v in values.items() if k in PARAMS}  # what RE restores
        self.values = dict(self.factory)
        self.saved = dict(self.factory)
        self.queued: dict[str, Any] = {}

    def knows(self, name: str) -> bool:
        return name in self.values

    def answer(self, name: str) -> bytes:
        v, size = self.values[name], self.params[name].size
        return bytes(v) if size == TEXT else int(v).to_bytes(size, "big")

    def check(self, name: str, parameter: bytes) -> tuple[int, Any]:
        """(status, value) of a set request: status 0 with the decoded value, or an error."""
        p = self.params[name]
        if not p.writable:
            return AtStatus.ERROR, None
        if p.size == TEXT:
            value: Any = bytes(parameter)
        elif len(parameter) > p.size:
            return AtStatus.INVALID_PARAMETER, None
        else:
            value = int.from_bytes(parameter, "big")
        return (AtStatus.OK, value) if p.valid(value) else (AtStatus.INVALID_PARAMETER, None)

    def command(self, name: str, parameter: bytes, apply: bool) -> tuple[int, bytes, bool]:
        """A register read (no parameter) or set: (status, value, applied). A set is queued,
        and applied at once when *apply* (0x08, or 0x17 with the apply option)."""
        if not self.knows(name):
            return AtStatus.INVALID_COMMAND, b"", False
        if not parameter:
            return AtStatus.OK, self.answer(name), False
        status, v = self.check(name, parameter)
        if status != AtStatus.OK:
            return status, b"", False
        self.queued[name] = v
        if apply:
            self.apply()
        return status, b"", apply

    def apply(self) -> None:
        self.values.update(self.queued)
        self.queued.clear()

    def write(self) -> None:
        self.saved = dict(self.values)

    def restore_defaults(self) -> None:
        self.values = dict(self.factory)
        self.queued.clear()

    def reset(self) -> None:
        """Software reset: back to what WR saved; the queue is lost."""
        self.values = dict(self.saved)
        self.queued.clear()


class Reply(NamedTuple):
    """An answer frame waiting for the UART: frame data, whether AP/BD may change after it
    has been sent, and whether it is the first frame after a power-up (the registers are
    back to what WR saved before it is sent)."""

    data: bytes
    reconfigure: bool = False
    power_up: bool = False


class Output(NamedTuple):
    t_ns: int
    item: Any  # Reply, or an RF packet (rendered when the UART takes it)


@dataclass
class Remote:
    """A node the coordinator can reach over the link: its registers and role."""

    registers: Registers
    device_type: int = 1  # router

    @property
    def addr64(self) -> int:
        return self.registers.values["SH"] << 32 | self.registers.values["SL"]

    @property
    def addr16(self) -> int:
        return self.registers.values["MY"]


def identity_registers(identity: dict[str, Any], **overrides) -> Registers:
    """Registers of a module from a scenario's radio identity (AT name -> value)."""
    values = dict(DEFAULTS)
    for k, v in identity.items():
        k = k.upper()
        if k in PARAMS:
            values[k] = v.encode("ascii") if isinstance(v, str) and PARAMS[k].size == TEXT else v
    values.update(overrides)
    return Registers(values)


@dataclass
class Coordinator:
    """Coordinator state machine; pure function of its inputs and its generator.

    ``received`` and ``host`` return :class:`Output` items for the coordinator's UART;
    ``admit`` takes or drops an item when it reaches the serial transmit buffer; ``render``
    turns an item into the bytes of an API frame at the moment the UART starts sending it
    (so AP changes apply to every frame sent after the change).
    """

    registers: Registers
    remotes: list[Remote]
    link: Any  # .unicast(t_ns, nbytes, air=None) -> (delivered, retries, latency_ns)
    rng: np.random.Generator
    response_delay_ns: int = RESPONSE_DELAY_NS
    faults: tuple = ()  # emulator.faults acting on the coordinator: off while one is active
    escaped: bool = field(init=False)
    baud: int = field(init=False)
    reset_until_ns: int = field(default=-1, init=False)
    ignored: int = field(default=0, init=False)  # host frames the firmware does not handle
    dropped_tx_buffer: int = field(default=0, init=False)  # RF packets the UART had no room for
    room: int = field(default=SERIAL_TX_BUFFER, init=False)  # the serial transmit buffer's bytes
    _prefix: dict = field(default_factory=dict, init=False)
    #: the API frames of RF packets admitted and not yet rendered, by (AP 2, AO bit 0,
    #: packet): the frame is a function of the three, so render takes what admit made
    _framed: dict = field(default_factory=dict, init=False)
    #: the frames its transmit requests put on the air (emulator.radio.AirFrame), in the order
    #: sent, until the run takes them
    air: list = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        self._sync_line()
        self._decoder = XBeeDecoder(self.escaped)
        self._sender = Sender(self.registers.values["OI"])

    # -- UART side ------------------------------------------------------------------------
    def _sync_line(self) -> None:
        self.escaped = self.registers.values["AP"] == 2
        self.baud = xbee.baud_rate(self.registers.values["BD"])

    def admit(self, t_ns: int, item, queued: int) -> int | None:
        """An item reaching the serial transmit buffer at *t_ns*, with *queued* bytes ahead
        of it: its size in bytes, or None when it is not sent (RF packet: no room, or the
        radio is rebooting)."""
        if isinstance(item, Reply):
            return len(xbee.wrap(item.data, self.escaped))
        if t_ns < self.reset_until_ns or self.off(t_ns):
            self._framed.pop(self._rx_key(item), None)  # sized ahead, never sent
            return None
        frame = self._frame_of(item)
        if queued + len(frame) > self.room:
            self._framed.pop(self._rx_key(item))
            self.dropped_tx_buffer += 1
            return None
        return len(frame)

    def size(self, t_ns: int, item) -> int | None:
        """The bytes :meth:`render` will give for RF packet *item* reaching an empty buffer
        at *t_ns* and starting then, if the host changes nothing before (emulator.uart.Line
        looks ahead with it); None for a reply (its rendering may reconfigure the radio) or
        a packet that is not sent."""
        if isinstance(item, Reply) or t_ns < self.reset_until_ns or self.off(t_ns):
            return None
        n = len(self._frame_of(item))
        return n if n <= self.room else None

    def render(self, t_ns: int, item) -> bytes:
        """The API frame bytes of an output item, in the current API mode; b"" = nothing."""
        if isinstance(item, Reply):
            if item.power_up:
                self.registers.reset()
                self._reconfigure()
                self._decoder = XBeeDecoder(self.escaped)  # a half-read frame is gone
            out = xbee.wrap(item.data, self.escaped)
            if item.reconfigure:
                self._reconfigure()
            return out
        frame = self._framed.pop(self._rx_key(item), None)  # first: kept for nothing else
        if t_ns < self.reset_until_ns or self.off(t_ns):
            return b""  # the radio is rebooting: the packet is never reported
        return self._rx_frame(item) if frame is None else frame

    def render_all(self, ready, items) -> tuple[bytes, list[int]] | None:
        """:meth:`render` of every item, ready at *ready* (ascending), all admitted: their
        frames end to end and each one's size (emulator.uart Line.drain); None where a
        rendering would change the radio (a power-up or reconfiguring reply) or the radio
        is off or resetting at some item."""
        if self.faults or (len(ready) and ready[0] < self.reset_until_ns):
            return None
        prefix, parts = self._rx_prefix, []
        for item in items:
            if type(item) is Reply:
                if item.power_up or item.reconfigure:
                    return None
                parts += (b"", item.data)
            else:
                parts += (prefix(item), item.data)
        data, sizes = xbee.wrap_many(b"".join(parts), np.fromiter(
            map(len, parts), np.int64, len(parts)).reshape(-1, 2).sum(axis=1), self.escaped)
        return data, sizes

    def _rx_key(self, pkt) -> tuple:
        return self.escaped, self.registers.values["AO"] & 1, pkt

    def _frame_of(self, pkt) -> bytes:
        """The API frame of RF packet *pkt* in the current modes, built once: kept for
        admit and render (render takes it)."""
        key = self._rx_key(pkt)
        frame = self._framed.get(key)
        if frame is None:
            frame = self._framed[key] = self._rx_frame(pkt)
        return frame

    def _rx_frame(self, pkt) -> bytes:
        """The API frame reporting RF packet *pkt* (0x90 or 0x91), in the current modes."""
        return xbee.wrap(self._rx_prefix(pkt) + pkt.data, self.escaped)

    def _rx_prefix(self, pkt) -> bytes:
        """Frame data of a 0x90 (or 0x91) up to the payload, built once per sender."""
        explicit = bool(self.registers.values["AO"] & 1)
        key = (explicit, pkt.src64, pkt.src16, pkt.options)
        prefix = self._prefix.get(key)
        if prefix is None:
            if explicit:
                src_ep, dst_ep, cluster, profile = DIGI_DATA
                prefix = xbee.frame_data(FrameType.EXPLICIT_RX, src64=pkt.src64, src16=pkt.src16,
                                         src_endpoint=src_ep, dest_endpoint=dst_ep,
                                         cluster=cluster, profile=profile, options=pkt.options,
                                         data=b"")
            else:
                prefix = xbee.frame_data(FrameType.RECEIVE_PACKET, src64=pkt.src64,
                                         src16=pkt.src16, options=pkt.options, data=b"")
            self._prefix[key] = prefix
        return prefix

    def _reconfigure(self) -> None:
        was = self.escaped
        self._sync_line()
        if self.escaped != was:
            self._decoder = XBeeDecoder(self.escaped)

    # -- events -----------------------------------------------------------------------------
    def power_up(self, t_ns: int = 0) -> list[Output]:
        """Modem status 0x00 (hardware reset) at *t_ns*, then 0x06 (coordinator started);
        after a power cut (a coordinator fault), with the registers WR saved."""
        return [Output(t_ns, self._modem(ModemStatus.HARDWARE_RESET)._replace(power_up=t_ns > 0)),
                Output(t_ns + POWER_UP_START_NS, self._modem(ModemStatus.COORDINATOR_STARTED))]

    def off(self, t_ns: int) -> bool:
        """Whether a coordinator fault has the radio powered off at *t_ns*."""
        return bool(self.faults) and any(f.active(t_ns) for f in self.faults)

    def received(self, t_ns: int, packet) -> Output:
        """An RF packet the radio received at *t_ns*: reported as a 0x90/0x91 frame. The
        sender's 16-bit address is learnt from it (a router that rejoined has a new one)."""
        self.received_all([packet])
        return Output(t_ns, packet)

    def received_all(self, packets: list) -> None:
        """:meth:`received` of each of *packets*, in order (each reported at its time): a
        remote's MY ends as the last of its packets has it."""
        last = {p.src64: p.src16 for p in packets}
        for r in self.remotes:
            if r.addr64 in last and r.addr16 != last[r.addr64]:
                r.registers.values["MY"] = last[r.addr64]

    def host(self, t_ns: int, data: bytes) -> list[Output]:
        """Bytes the host wrote, arriving at *t_ns*: the answers they cause."""
        if self.off(t_ns):
            return []  # a radio without power reads nothing
        out: list[Output] = []
        for ev in self._decoder.feed(data):
            if not isinstance(ev, Frame):
                continue  # firmware drops frames with bad checksums silently
            handler = self._HANDLERS.get(ev.type)
            if handler is None:
                self.ignored += 1
                continue
            out += handler(self, t_ns, ev.fields)
        return out

    # -- frame builders -------------------------------------------------------------------
    @staticmethod
    def _modem(status: int) -> Reply:
        return Reply(xbee.frame_data(FrameType.MODEM_STATUS, status=status))

    @staticmethod
    def _at_reply(frame_id: int, command: bytes, status: int, value: bytes = b"",
                  reconfigure: bool = False) -> Reply:
        return Reply(xbee.frame_data(FrameType.AT_RESPONSE, frame_id=frame_id, command=command,
                                     status=status, value=value), reconfigure)

    # -- local AT ---------------------------------------------------------------------------
    def _at(self, t_ns: int, f: dict, queued: bool) -> list[Output]:
        fid, raw_cmd, param = f["frame_id"], f["command"], f["parameter"]
        name = raw_cmd.decode("ascii", "replace").upper()
        t = t_ns + self.response_delay_ns
        reg = self.registers
        extra: list[Output] = []
        reconfigure = False
        value = b""
        if name == "ND":  # only the nodes answer, no OK of its own
            return self._discover(t_ns, fid, raw_cmd, param)
        if name in EXECUTE:
            status, reconfigure, extra = self._execute(name, t_ns)
        else:
            status, value, reconfigure = reg.command(name, param, apply=not queued)
        if fid == 0:
            if reconfigure:
                self._reconfigure()
            return extra
        return [Output(t, self._at_reply(fid, raw_cmd, status, value, reconfigure)), *extra]

    def _execute(self, name: str, t_ns: int):
        """(status, reconfigure, later outputs) of AC, WR, RE or FR."""
        reg = self.registers
        if name == "AC":
            reg.apply()
            return AtStatus.OK, True, []
        if name == "WR":
            reg.write()
            return AtStatus.OK, False, []
        if name == "RE":
            reg.restore_defaults()
            return AtStatus.OK, True, []
        t = t_ns + self.response_delay_ns  # FR
        reg.reset()
        self.reset_until_ns = t + RESET_NS + START_NS
        return AtStatus.OK, True, [
            Output(t + RESET_NS, self._modem(ModemStatus.WATCHDOG_RESET)),
            Output(t + RESET_NS + START_NS, self._modem(ModemStatus.COORDINATOR_STARTED))]

    def _discover(self, t_ns: int, fid: int, raw_cmd: bytes, wanted_ni: bytes) -> list[Output]:
        """ND: each remote answers after a random delay within NT x 100 ms, over the link."""
        window = self.registers.values["NT"] * 100 * MS
        no = self.registers.values["NO"]
        out = []
        for node in self.remotes:
            delay = int(self.rng.integers(self.response_delay_ns, window))
            if wanted_ni and bytes(wanted_ni) != node.registers.values["NI"]:
                continue
            delivered, _, latency = self.link.unicast(t_ns + delay, 32)
            if not delivered or delay + latency >= window or fid == 0:
                continue
            r = node.registers.values
            value = (r["MY"].to_bytes(2, "big") + r["SH"].to_bytes(4, "big")
                     + r["SL"].to_bytes(4, "big") + bytes(r["NI"]) + b"\x00"
                     + (0xFFFE).to_bytes(2, "big") + bytes((node.device_type, 0))
                     + DIGI_PROFILE.to_bytes(2, "big") + xbee.DIGI_MANUFACTURER.to_bytes(2, "big")
                     + (r["DD"].to_bytes(4, "big") if no & 1 else b""))
            out.append(Output(t_ns + delay + latency,
                              self._at_reply(fid, raw_cmd, AtStatus.OK, value)))
        return out

    # -- transmit ---------------------------------------------------------------------------
    def _find(self, addr64: int, addr16: int) -> Remote | None:
        for node in self.remotes:
            if addr64 == node.addr64 or (addr64 == 0xFFFFFFFFFFFFFFFF and addr16 == node.addr16):
                return node
        return None

    def _own(self, addr64: int) -> bool:
        r = self.registers.values
        return addr64 in (r["SH"] << 32 | r["SL"], xbee.COORDINATOR64)

    def _transmit(self, t_ns: int, f: dict) -> list[Output]:
        fid, dest64, dest16, data = f["frame_id"], f["dest64"], f["dest16"], f["data"]
        t = t_ns + self.response_delay_ns
        np_limit = self.registers.values["NP"]
        retries = discovery = 0
        to16 = dest16
        answers: list[Output] = []
        if dest64 == xbee.BROADCAST64:
            status = (DeliveryStatus.PAYLOAD_TOO_LARGE
                      if len(data) > np_limit + BROADCAST_PAYLOAD_EXTRA else DeliveryStatus.SUCCESS)
            to16 = xbee.UNKNOWN16
        elif len(data) > np_limit:
            status = DeliveryStatus.PAYLOAD_TOO_LARGE
        elif self._own(dest64):
            status, to16 = DeliveryStatus.SELF_ADDRESSED, self.registers.values["MY"]
        elif (node := self._find(dest64, dest16)) is None:
            status = (DeliveryStatus.ROUTE_NOT_FOUND if dest64 == 0xFFFFFFFFFFFFFFFF
                      else DeliveryStatus.ADDRESS_NOT_FOUND)
            t += ADDRESS_TIMEOUT_NS
            to16 = 0xFFFD
        else:
            delivered, retries, latency = self.link.unicast(
                t_ns, len(data), air=lambda attempts: self._on_air(attempts, node, f))
            t = t_ns + max(self.response_delay_ns, latency)
            status = DeliveryStatus.SUCCESS if delivered else DeliveryStatus.NETWORK_ACK_FAILURE
            to16 = node.addr16 if delivered else 0xFFFD
            discovery = 0x01 if dest16 == xbee.UNKNOWN16 else 0x00
            if delivered and f.get("dest_endpoint") == 0 and f.get("profile") == 0:
                answers = self._zdo(t_ns + latency, f, node)
        if fid == 0:
            return answers
        return [Output(t, Reply(xbee.frame_data(
            FrameType.TRANSMIT_STATUS, frame_id=fid, dest16=to16, retries=min(retries, 0xFF),
            delivery=status, discovery=discovery))), *answers]

    def _on_air(self, attempts, node: Remote, f: dict) -> None:
        """Transmit request *f*'s attempts to *node* as frames on the air (a 0x11's own
        endpoints, cluster and profile; its radius, 0 meaning NH)."""
        aps = {k: f[k] for k in ("src_endpoint", "dest_endpoint", "cluster", "profile") if k in f}
        self.air += self._sender.frames(attempts, 0, self.registers.values["MY"], node.addr16,
                                        f["data"], f.get("radius") or self.registers.values["NH"],
                                        **aps)

    def _zdo(self, t_ns: int, f: dict, node: Remote) -> list[Output]:
        """The node's answer to a ZDO request it received at *t_ns* (emulator.zdo): a 0x91
        when it comes back over the link and AO bit 0 is set (ZB firmware passes ZDO
        answers to the host only then; AO is taken when the request is sent)."""
        answer = zdo.answer(f["cluster"], f["data"], node.addr16, node.device_type)
        if answer is None or not self.registers.values["AO"] & 1:
            return []
        cluster, payload = answer
        back, _, latency = self.link.unicast(t_ns, len(payload))
        if not back:
            return []
        return [Output(t_ns + max(self.response_delay_ns, latency), Reply(xbee.frame_data(
            FrameType.EXPLICIT_RX, src64=node.addr64, src16=node.addr16, src_endpoint=0,
            dest_endpoint=0, cluster=cluster, profile=0, options=ZDO_RX_OPTIONS,
            data=payload)))]

    # -- remote AT --------------------------------------------------------------------------
    def _remote_at(self, t_ns: int, f: dict) -> list[Output]:
        fid, raw_cmd, param = f["frame_id"], f["command"], f["parameter"]
        name = raw_cmd.decode("ascii", "replace").upper()
        node = self._find(f["dest64"], f["dest16"])
        value = b""
        if node is None:
            status, t = AtStatus.TX_FAILURE, t_ns + self.response_delay_ns + ADDRESS_TIMEOUT_NS
            src64, src16 = f["dest64"], f["dest16"]
        else:
            src64, src16 = node.addr64, node.addr16
            there, _, lat1 = self.link.unicast(t_ns, 4 + len(param))
            back, _, lat2 = self.link.unicast(t_ns + lat1, 8) if there else (False, 0, 0)
            t = t_ns + max(self.response_delay_ns, lat1 + lat2)
            reg = node.registers
            if not there:
                status = AtStatus.TX_FAILURE
            elif name in ("AC", "WR"):
                (reg.apply if name == "AC" else reg.write)()
                status = AtStatus.OK
            else:  # options bit 1: apply changes
                status, value, _ = reg.command(name, param, apply=bool(f["options"] & 0x02))
            if there and not back:
                status, value = AtStatus.TX_FAILURE, b""
        if fid == 0:
            return []
        return [Output(t, Reply(xbee.frame_data(
            FrameType.REMOTE_AT_RESPONSE, frame_id=fid, src64=src64, src16=src16,
            command=raw_cmd, status=status, value=value)))]

    _HANDLERS = {
        FrameType.AT_COMMAND: lambda self, t, f: self._at(t, f, queued=False),
        FrameType.AT_COMMAND_QUEUE: lambda self, t, f: self._at(t, f, queued=True),
        FrameType.TRANSMIT_REQUEST: _transmit,
        FrameType.EXPLICIT_ADDRESSING: _transmit,
        FrameType.REMOTE_AT_REQUEST: _remote_at,
    }
