"""Wire formats: a name (``navtwin decode --format``, a port declaration's ``format``) ->
its streaming decoder, and how its frames read as JSON records.

A :class:`Format` is registered in :data:`FORMATS` (the lab's four built in; installed
packages add theirs in the ``navtwin.formats`` entry-point group). A frame's ``format``
(protocols.stream.Frame) is the name of the format that declares its layout, so a chain's
frames (``xbee-sins``: XBee API frames carrying SINS frames) are rendered and handled by the
format of each layer.

API mode. The formats whose bytes are XBee API frames (``api_mode``) are decoded in API
mode 2 (escaped) or 1, as the recording or the host's ``--api1`` says; the others have one
framing and take no mode.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, Callable

from .plugins import Registry, load


class FormatError(ValueError):
    """A format declaration that cannot be registered; one line naming the fix."""


def hexval(v):
    if isinstance(v, bytes):
        return v.hex().upper()
    if isinstance(v, tuple):
        return [hexval(x) for x in v]
    return v


def plain_record(frame, gyro_range: int) -> dict:
    """Fields as they are, bytes in hex: a format that declares no rendering of its own."""
    return {k: hexval(v) for k, v in frame.fields.items()}


@dataclass(frozen=True)
class Format:
    """One wire format.

    *decoder*: makes a fresh streaming decoder (protocols.stream: ``feed``, ``flush``,
    ``summary``, ``bytes``, ``frames``); called with ``escaped`` when *api_mode*.
    *record(frame, gyro_range)*: a frame's fields as JSON-able values with engineering units.
    Either may be given as ``"module:attribute"``, imported when first used (the command
    line lists the formats without importing the frame layouts).
    *labelled(frame, gyro_range)*: optional, a frame's fields by name as ``(raw, value in
    engineering units or None, unit)``, for ``navtwin diff`` (``ZGYRO_OUT 0x8123 -> 0x8124
    (+0.07326 deg/s)``); without it a diff names the fields of *record*.
    *carries*: what the host makes of the frames: ``imu`` samples, ``ranges``, ``radio``
    (the coordinator's own frames: link quality, API mode); other frames are counted.
    """

    name: str
    decoder: Callable[..., Any] | str
    doc: str
    api_mode: bool = False
    record: Callable[[Any, int], dict] | str = plain_record
    carries: str = ""
    labelled: Callable[[Any, int], dict] | str | None = None

    @cached_property
    def _decoder(self) -> Callable[..., Any]:
        return load(self.decoder) if isinstance(self.decoder, str) else self.decoder

    @cached_property
    def render(self) -> Callable[[Any, int], dict]:
        """*record*, imported."""
        return load(self.record) if isinstance(self.record, str) else self.record

    @cached_property
    def label(self) -> Callable[[Any, int], dict]:
        """*labelled*, imported."""
        return load(self.labelled) if isinstance(self.labelled, str) else self.labelled

    def make(self, *, escaped: bool = True):
        """A fresh decoder (*escaped*: XBee API mode 2, for the formats with an API mode)."""
        return self._decoder(escaped) if self.api_mode else self._decoder()


def _check(name: str, fmt) -> None:
    if not isinstance(fmt, Format):
        raise FormatError(f"format {name!r} is a {type(fmt).__name__}, not a "
                          "navtwin.protocols.formats.Format; declare it with Format(...)")
    if fmt.name != name:
        raise FormatError(f"format declared as {fmt.name!r} is registered as {name!r}; use one "
                          "name")


_STREAM, _DECODE = "navtwin.protocols.stream", "navtwin.protocols.decode"
SINS = Format("sins", f"{_STREAM}:sins_decoder", "the SINS board's frames",
              record=f"{_DECODE}:sins_record", carries="imu",
              labelled=f"{_DECODE}:sins_labelled")
NANOLOC = Format("nanoloc", f"{_STREAM}:nanoloc_decoder", "the nanoLOC gateway's reports",
                 record=f"{_DECODE}:nanoloc_record", carries="ranges")
XBEE = Format("xbee", f"{_STREAM}:XBeeDecoder", "XBee API frames", api_mode=True,
              record=f"{_DECODE}:xbee_record", carries="radio")
XBEE_SINS = Format("xbee-sins", f"{_STREAM}:XBeeSinsChain",
                   "the SINS stream rebuilt from XBee 0x90 packets", api_mode=True)

FORMATS: Registry[Format] = Registry("navtwin.formats", "format",
                                     {f.name: f for f in (SINS, NANOLOC, XBEE, XBEE_SINS)},
                                     check=_check, error=FormatError)


def get(name: str) -> Format:
    """The format *name*; :class:`FormatError` naming the known ones if there is none."""
    if name not in FORMATS:
        raise FormatError(FORMATS.unknown([name]))
    return FORMATS.get(name)
