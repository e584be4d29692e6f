"""Fault kinds: the ``[[faults]]`` entries of a scenario, one class per kind, in a registry.

A kind is a frozen dataclass of its settings (the schema: ``key(...)`` fields, checked on
load and listed in docs/scenarios.md) with a class attribute ``KIND`` (its ``kind = "..."``
name) and ``ACTS_ON`` (the model it acts on, one of :data:`MODELS`), registered with
:func:`register`.

Schedule (every kind). An episode runs from ``start_s`` to ``end_s`` (exclusive); without
them a fault lasts the whole run (``start_s`` 0, ``end_s`` the longest run). With
``repeat_s`` it recurs: episode k runs from ``start_s + k * repeat_s`` for ``end_s -
start_s`` seconds (``repeat_s`` longer than that, so episodes never touch), until an episode
would start at or after ``until_s`` (none: to the end of the run). :meth:`Fault.active`
tells which times (an int or a numpy array of ns) fall in an episode.

A kind acts in one of two places:

- on a device model (:class:`DeviceFault`): the model asks :func:`acting_on` for the faults
  on it (an anchor by id, the RF link, a vehicle's board, the coordinator) and calls each one's ``act(effect, on)`` with the
  model's effects of one block (``on``: which of the block's events fall in the episode);
  the model defines what ``effect`` holds (emulator.nanoloc.ExchangeEffects,
  emulator.radio.AttemptEffects);
- on a port's UART line (:class:`LineFault`): ``wrapper(rng)`` gives an
  emulator.uart.LineWrapper, which the Emulation puts between the port's device and its line;
  it sees every chunk the device sends and may change, drop, delay or add bytes.
  ``direction = "to_device"`` puts it on the bytes the host writes instead (only the xbee
  coordinator reads them). Its wrapper marks what it did (``LineWrapper.mark``) and the
  line writes each mark into the run's fault ledger (emulator.ledger).

The registry is :data:`KINDS` (also ``Fault.KINDS``, which common.schema reads): the shipped
kinds declared by ``"module:class"`` below (the order of the docs table), those added in process
with :func:`register`, then the kinds of installed packages, from the entry-point group
``navtwin.faults`` (name = the kind, value = the class), each imported when first used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from navtwin.common.anchorgrid import WIDE_ANCHOR_IDS
from navtwin.common.limits import MAX_DURATION_S, VEHICLES
from navtwin.protocols.plugins import Registry
from navtwin.common.schema import REQUIRED, Check, Invalid, between, key, non_negative, one_of
from navtwin.protocols import ports

ENTRY_POINTS = "navtwin.faults"
#: what a fault can act on: an anchor's exchanges, the XBee RF link, a vehicle's SINS board
#: or XBee router, the lab computer's XBee coordinator, a port's UART line
MODELS = ("anchor", "link", "board", "router", "coordinator", "line")
#: which bytes a line fault acts on: what the device sends the host, or what the host writes
DIRECTIONS = ("to_host", "to_device")
_LAB_PORTS = ", ".join(map(repr, ports.PORTS.built_in))
#: a line's port: the lab's or one an installed package declares (protocols.ports), or a
#: vehicle's instance of one (sins2); the scenario checks that it has that vehicle
DECLARED_PORT = Check(ports.known, f"must be one of {_LAB_PORTS}, a port a package declares, "
                      "or vehicle n's (sins2)", f"use one of {_LAB_PORTS}, or install the package "
                      "that declares the port")
#: The shortest episode and period: the emulator keeps time in integer ns, and a schedule
#: finer than these only multiplies episodes (each a power-up, a Poisson draw) with nothing
#: to act on, until a run of seconds takes hours or a float of ns overflows.
MIN_EPISODE_S = 1e-6
MIN_REPEAT_S = 1e-3


class FaultError(ValueError):
    """A fault kind that cannot be registered; one line naming the fix."""


@dataclass(frozen=True, kw_only=True)
class Fault:
    """One episode of a fault; subclasses add their settings."""

    KINDS = None  # the registry of kinds (a protocols.plugins.Registry), set below; common.schema reads it
    KIND = ""
    ACTS_ON = ""
    start_s: float = key(0.0, "s", "start of the episode", non_negative(hi=MAX_DURATION_S))
    end_s: float | None = key(None, "s", "end of the episode (exclusive); none = the end of "
                              "the run", non_negative(hi=MAX_DURATION_S))

    repeat_s: float | None = key(None, "s", "period: the episode recurs every repeat_s from "
                                 "start_s; none = once", between(MIN_REPEAT_S, MAX_DURATION_S))
    until_s: float | None = key(None, "s", "with repeat_s: no episode starts at or after "
                                "until_s; none = to the end", non_negative(hi=MAX_DURATION_S))

    def __post_init__(self):
        if self.end_s is None:
            if self.repeat_s is not None:
                raise Invalid("end_s", "is missing; a repeating fault needs the end of its first "
                                       "episode: add end_s = <s>")
            # to the end of the run: the longest run ends before this (frozen: set it once)
            object.__setattr__(self, "end_s", float(MAX_DURATION_S))
        if self.end_s - self.start_s < MIN_EPISODE_S:
            raise Invalid("end_s", f"must be after start_s, by {MIN_EPISODE_S:g} s at least (got "
                                   f"{self.end_s:g} after {self.start_s:g} s); make end_s later")
        length = self.end_s - self.start_s
        if self.repeat_s is not None and self.repeat_s <= length:
            raise Invalid("repeat_s", f"must be longer than the episode ({self.repeat_s:g} <= "
                                      f"{length:g} s), so episodes do not run together; make "
                                      "repeat_s > end_s - start_s or make one longer episode")
        if self.until_s is not None and (self.repeat_s is None or self.until_s <= self.start_s):
            raise Invalid("until_s", "needs repeat_s and must be after start_s; set repeat_s, "
                                     "or drop until_s")

    def _phase(self, t_ns):
        """(episode number, ns since that episode began) of time(s) *t_ns* at or after start."""
        since = t_ns - self.start_s * 1e9
        if self.repeat_s is None:
            return 0 * since, since
        k = since // (self.repeat_s * 1e9)
        return k, since - k * (self.repeat_s * 1e9)

    def active(self, t_ns):
        """Whether true time(s) *t_ns* (an int or a numpy array of ns) fall in an episode."""
        if self.repeat_s is None:
            return (t_ns >= self.start_s * 1e9) & (t_ns < self.end_s * 1e9)
        k, phase = self._phase(t_ns)
        on = (t_ns >= self.start_s * 1e9) & (phase < (self.end_s - self.start_s) * 1e9)
        if self.until_s is not None:
            on = on & (self.start_s * 1e9 + k * (self.repeat_s * 1e9) < self.until_s * 1e9)
        return on

    def episode_end(self, t_ns: int) -> int:
        """The first ns after the episode that *t_ns* falls in (which must be active)."""
        k, phase = self._phase(t_ns)
        end = t_ns - phase + (self.end_s - self.start_s) * 1e9
        return max(math.ceil(end), t_ns + 1)

    def at_active(self, active_ns: float) -> int | None:
        """The time at which *active_ns* of episode time have passed since the first
        episode began (a Poisson process in episode time maps onto the run so); None if
        the episodes end before."""
        length = (self.end_s - self.start_s) * 1e9
        k = active_ns // length
        if k and self.repeat_s is None:
            return None
        begin = self.start_s * 1e9 + k * (self.repeat_s or 0) * 1e9
        if self.until_s is not None and begin >= self.until_s * 1e9:
            return None
        t = math.ceil(begin + active_ns - k * length)
        return t if self.active(t) else None  # a float edge at the episode's end

    def next_active(self, t_ns: int) -> int | None:
        """The first ns at or after *t_ns* inside an episode; None if no episode is left."""
        if self.active(t_ns):
            return t_ns
        if t_ns < self.start_s * 1e9:
            return math.ceil(self.start_s * 1e9)
        if self.repeat_s is None:
            return None
        k, _ = self._phase(t_ns)
        begin = self.start_s * 1e9 + (k + 1) * (self.repeat_s * 1e9)
        if self.until_s is not None and begin >= self.until_s * 1e9:
            return None
        t = math.ceil(begin)
        return t if self.active(t) else t + 1  # a float edge one ns short


@dataclass(frozen=True, kw_only=True)
class DeviceFault(Fault):
    """A fault that changes what a device model does (ACTS_ON "anchor", "link", "board" or
    "coordinator"). Its frames reach the host intact (lab.audit: CHANGES_BYTES)."""

    CHANGES_BYTES = False

    def act(self, effect, on):
        """Change the model's *effect* of one block where the boolean array *on* is set;
        return the events it changed (a boolean array) when that is not all of *on* (the
        ledger marks those), else None."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class AnchorFault(DeviceFault):
    """A fault on one anchor's exchanges."""

    ACTS_ON = "anchor"
    anchor: int = key(REQUIRED, "", "anchor id", between(*WIDE_ANCHOR_IDS))


@dataclass(frozen=True, kw_only=True)
class BoardFault(DeviceFault):
    """A fault on one vehicle's SINS board."""

    ACTS_ON = "board"
    vehicle: int = key(1, "", "the vehicle whose board it is, 1 = the first", between(*VEHICLES))


@dataclass(frozen=True, kw_only=True)
class RouterFault(DeviceFault):
    """A fault on one vehicle's XBee router."""

    ACTS_ON = "router"
    vehicle: int = key(1, "", "the vehicle whose router it is, 1 = the first", between(*VEHICLES))


@dataclass(frozen=True, kw_only=True)
class CoordinatorFault(DeviceFault):
    """A fault on an XBee coordinator: the one every router joined, or with a coordinator
    per vehicle (``[xbee] network = "per-vehicle"``) vehicle *vehicle*'s."""

    ACTS_ON = "coordinator"
    vehicle: int = key(1, "", "with a coordinator per vehicle, the vehicle whose coordinator it "
                       "is; 1 = the first (the only one of a shared network)", between(*VEHICLES))


@dataclass(frozen=True, kw_only=True)
class LineFault(Fault):
    """A fault on the bytes of one port's line, between the device and the client."""

    ACTS_ON = "line"
    #: False for a kind that only moves bytes in time (latency, bandwidth, slicing): the
    #: audit (lab.audit) then expects the far side to accept every frame it touched
    CHANGES_BYTES = True
    port: str = key(REQUIRED, "", "the port whose line it acts on", DECLARED_PORT)
    direction: str = key("to_host", "", "the bytes it acts on: to_host (the device's) or "
                         "to_device (the host's; xbee only)", one_of(*DIRECTIONS))

    def __post_init__(self):
        super().__post_init__()
        if self.direction == "to_device" and not ports.get(self.port).host_writes:
            reading = [p.name for p in ports.listed() if p.host_writes]
            raise Invalid("direction", f"to_device on {self.port}: its device ignores what the host "
                                       f"writes; use port = {' or '.join(map(repr, reading))} "
                                       'or direction = "to_host"')

    def wrapper(self, rng):
        """The emulator.uart.LineWrapper to install; *rng* is this fault's own stream."""
        raise NotImplementedError


def _check(kind: str, cls) -> None:
    if not (isinstance(cls, type) and issubclass(cls, (DeviceFault, LineFault))):
        raise FaultError(f"{cls!r} is not a DeviceFault or LineFault subclass; derive the kind "
                         "from navtwin.emulator.faults.DeviceFault or LineFault")
    if not cls.KIND or cls.KIND != kind or cls.ACTS_ON not in MODELS:
        raise FaultError(f"{cls.__name__} needs KIND = {kind!r} (its name) and ACTS_ON (one of "
                         f"{', '.join(MODELS)}); set both class attributes")


#: The fault kinds: the shipped ones in the order of the docs table, then registered, then
#: entry points.
KINDS: Registry[type[Fault]] = Registry(ENTRY_POINTS, "fault kind", {
    kind: f"navtwin.emulator.faults.{kind}:{cls}" for kind, cls in (
        ("anchor_outage", "AnchorOutage"), ("nlos", "Nlos"), ("link_loss", "LinkLoss"),
        ("link_fade", "LinkFade"), ("range_value_error", "RangeValueError"),
        ("board_reset", "BoardReset"), ("coordinator_reset", "CoordinatorReset"),
        ("router_rejoin", "RouterRejoin"), ("bit_errors", "BitErrors"), ("byte_drop", "ByteDrop"),
        ("byte_duplicate", "ByteDuplicate"), ("byte_insert", "ByteInsert"),
        ("garbage", "Garbage"), ("burst_loss", "BurstLoss"), ("latency", "Latency"),
        ("bandwidth", "Bandwidth"), ("slicing", "Slicing"), ("stuck", "Stuck"))},
    check=_check, error=FaultError)
Fault.KINDS = KINDS


def register(cls: type[Fault]) -> type[Fault]:
    """Add kind *cls* under its KIND (a class decorator); FaultError if it cannot be."""
    _check(getattr(cls, "KIND", None), cls)  # before the registry reads KIND as the name
    return KINDS.register(cls.KIND, cls)


unregister = KINDS.unregister


def acting_on(faults, model: str, **which) -> list[Fault]:
    """The faults of *faults* that act on *model*, with attributes equal to *which* (for
    example ``anchor=3``), in scenario order."""
    return [f for f in faults if f.ACTS_ON == model
            and all(getattr(f, name, None) == v for name, v in which.items())]
