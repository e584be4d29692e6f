"""The Python API under ``navtwin decode``: sources of bytes, and frames as JSON-able dicts."""
from __future__ import annotations

import math
import os
import stat
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

from . import adis16350, adis16488, formats, nanoloc, ports, sins, xbee
from .ports import DEFAULT_BAUD
from .recording import Recording, RecordingError
from .formats import hexval
from .stream import DecodeError, Frame

CHUNK = 65536


def frame_record(ev: Frame, *, gyro_range: int = 300, with_hex: bool = False) -> dict:
    """One decoded frame as a JSON-able dict: raw fields plus engineering units."""
    rec: dict = {"format": ev.format, "offset": ev.offset, "type": ev.type}
    if ev.source is not None:
        rec["source"] = f"{ev.source:016X}"
    if not ev.known:
        rec["unknown_type"] = True
        rec["payload"] = ev.fields["payload"].hex().upper()
    else:
        rec.update(formats.get(ev.format).render(ev, gyro_range))
    if with_hex:
        rec["hex"] = ev.raw.hex().upper()
    return rec


def sins_record(frame: Frame, gyro_range: int) -> dict:
    f = frame.fields
    if frame.type == sins.TYPE_MAGNETOMETER:
        return magnetometer_record(frame)
    s = sins.to_sample(frame.type, f, gyro_range)
    words = ({"words": list(f["words"])} if frame.type == sins.TYPE_SAMPLE else
             {k: f[k] if isinstance(f[k], int) else list(f[k]) for k in _WIDE_FIELDS})
    return dict(seq=f["seq"], **words, nd=all(s.nd), ea=s.ea,
                gyro_dps=list(s.gyro_dps), gyro_rad_s=list(s.gyro_rad_s),
                accel_g=list(s.accel_g), accel_m_s2=list(s.accel_m_s2),
                temp_c=list(s.temp_c), supply_v=s.supply_v, aux_v=s.aux_v)


def magnetometer_record(frame: Frame) -> dict:
    """A magnetometer frame: its words and the field in uT (None on an axis overflow)."""
    f = frame.fields
    field = sins.field_ut(f["field"])
    return dict(seq=f["seq"], field_words=list(f["field"]),
                field_ut=None if field is None else list(field))


#: the words of a wide sample frame (type 03) in frame order, less ``seq``
_WIDE_FIELDS = ("supply", "gyro", "accel", "temp", "aux")

#: (unit, the Sample attribute and index) of each register word of a SINS frame, in order
_WORD_UNITS = (("V", "supply_v", None), *(("deg/s", "gyro_dps", i) for i in range(3)),
               *(("g", "accel_g", i) for i in range(3)), *(("degC", "temp_c", i) for i in range(3)),
               ("V", "aux_v", None))
#: the register (pair) names of a wide sample frame's words, in frame order
_WIDE_NAMES = ("SUPPLY_OUT", *adis16488.WORDS, "XTEMP_OUT", "YTEMP_OUT", "ZTEMP_OUT", "AUX_ADC")


def sins_labelled(frame: Frame, gyro_range: int) -> dict:
    """A SINS frame's fields for ``navtwin diff``: ``seq``, then each register word by its
    name (ZGYRO_OUT) with its value in engineering units."""
    f = frame.fields
    out: dict = {"seq": (f["seq"], None, "")}
    if frame.type == sins.TYPE_MAGNETOMETER:
        for axis, word in zip("XYZ", f["field"]):
            out[f"{axis}MAG"] = (word & 0xFFFF, None if word == sins.MAG_OVERFLOW else
                                 word * sins.MAG_LSB_UT, "uT")
        return out
    s = sins.to_sample(frame.type, f, gyro_range)
    if frame.type == sins.TYPE_SAMPLE:
        names, words = adis16350.REGISTERS, f["words"]
    else:  # the 32-bit words shown as unsigned, as the 16-bit ones are
        names = _WIDE_NAMES
        words = (f["supply"], *(w & 0xFFFFFFFF for w in (*f["gyro"], *f["accel"])), *f["temp"], f["aux"])
    for name, word, (unit, attr, i) in zip(names, words, _WORD_UNITS):
        v = getattr(s, attr)
        out[name] = (word, v if i is None else v[i], unit)
    return out


def nanoloc_record(frame: Frame, gyro_range: int) -> dict:
    f = frame.fields
    complete = nanoloc.is_complete(f["status"])
    rec = {k: f[k] for k in ("seq", "t_us", "anchor", "tag", "status", "rssi")}
    rec.update(complete=complete, tau_ps=list(f["tau"]),
               distance_m=nanoloc.distance(*f["tau"]) if complete else None)
    return rec


def xbee_record(frame: Frame, gyro_range: int) -> dict:
    rec = {"name": xbee.FRAME_NAMES.get(frame.type, "unknown")}
    for k, v in frame.fields.items():
        if k in ("src64", "dest64", "remote64"):
            rec[k] = f"{v:016X}"
        elif k in ("src16", "dest16", "remote16", "parent16"):
            rec[k] = f"{v:04X}"
        elif k == "command":
            rec[k] = v.decode("ascii", "replace")
        else:
            rec[k] = hexval(v)
    return rec


def _significant(x: float) -> int:
    """The significant digits of a constant as the datasheet writes it (0.018315: 5)."""
    return len(f"{x:.12e}".split("e")[0].replace(".", "").rstrip("0"))


def _decimals(lsb: float, significant: int = 1) -> int:
    """The decimals that print multiples of *lsb* to its resolution, given to *significant*
    digits: 0.07326 deg/s (4 digits) needs 5, so 12 counts print as 0.87912."""
    return max(0, significant - 1 - math.floor(math.log10(lsb)))


def _resolution(gyro_range: int) -> dict[str, int]:
    """Decimals of each engineering-unit field of a frame record: the ADIS16350's LSBs
    (converted ones keep their datasheet LSB's digits), and 1 ps in the ranging exchange."""
    out = {}
    for key, lsb in (("gyro_dps", adis16350.GYRO_LSB_DPS[gyro_range]),
                     ("accel_g", adis16350.ACCEL_LSB_G), ("temp_c", adis16350.TEMP_LSB_C),
                     ("supply_v", adis16350.SUPPLY_LSB_V), ("aux_v", adis16350.AUX_LSB_V)):
        out[key] = _decimals(lsb, _significant(lsb))
    digits = _significant(adis16350.GYRO_LSB_DPS[gyro_range])
    out["gyro_rad_s"] = _decimals(math.radians(adis16350.GYRO_LSB_DPS[gyro_range]), digits)
    out["accel_m_s2"] = _decimals(adis16350.ACCEL_LSB_G * adis16350.STANDARD_GRAVITY,
                                  _significant(adis16350.ACCEL_LSB_G))
    out["distance_m"] = _decimals(nanoloc.distance(1, 0, 0, 0))
    out["field_ut"] = _decimals(sins.MAG_LSB_UT, 4)
    return out


_DECIMALS = {rng: _resolution(rng) for rng in adis16350.GYRO_LSB_DPS}
#: a wide sample frame's 32-bit words to three significant digits of their LSB
_WIDE_DECIMALS = {"gyro_dps": _decimals(adis16488.GYRO_LSB_DPS, 3),
                  "gyro_rad_s": _decimals(math.radians(adis16488.GYRO_LSB_DPS), 3),
                  "accel_g": _decimals(adis16488.ACCEL_LSB_G, 3),
                  "accel_m_s2": _decimals(adis16488.ACCEL_LSB_G * adis16350.STANDARD_GRAVITY, 3)}


def printed(rec: dict, gyro_range: int = 300) -> dict:
    """*rec* as ``navtwin decode`` prints it: engineering units rounded to the sensor's
    resolution (0.87912, not 0.8791200000000001). The records themselves stay exact."""
    out = dict(rec)
    decimals = _DECIMALS[gyro_range]
    if "gyro" in rec:  # a wide sample's record (its 32-bit words): their finer resolution
        decimals = {**decimals, **_WIDE_DECIMALS}
    for key, places in decimals.items():
        v = rec.get(key)
        if isinstance(v, float):
            out[key] = round(v, places)
        elif isinstance(v, list):
            out[key] = [round(x, places) for x in v]
    return out


def error_record(ev: DecodeError) -> dict:
    rec = {"error": ev.kind, "format": ev.format, "offset": ev.offset, "size": ev.size}
    if ev.source is not None:
        rec["source"] = f"{ev.source:016X}"
    return rec


class ErrorRuns:
    """Errors of one kind (and format and source) with no frame between them as one record,
    so a flood of garbage gives a few lines, not one or two per byte: ``offset`` is the first's,
    ``size`` reaches to the furthest end of any of them, ``count`` (present when more than
    one) says how many and ``last_offset`` where the last began. A frame ends the runs."""

    def __init__(self) -> None:
        self._runs: dict[tuple, list] = {}  # key -> [first error, last offset, end, count]

    def add(self, ev: DecodeError) -> None:
        run = self._runs.get(key := (ev.kind, ev.format, ev.source))
        if run is None:
            self._runs[key] = [ev, ev.offset, ev.offset + ev.size, 1]
        else:
            run[1], run[2], run[3] = ev.offset, max(run[2], ev.offset + ev.size), run[3] + 1

    def close(self) -> Iterator[dict]:
        """The records of the runs open so far, in the order they began."""
        for first, last, end, count in self._runs.values():
            rec = error_record(first)
            if count > 1:
                rec.update(size=end - first.offset, count=count, last_offset=last)
            yield rec
        self._runs.clear()


def _is_serial(source: str) -> bool:
    if "://" in source:
        return True
    try:
        return stat.S_ISCHR(os.stat(source).st_mode)
    except OSError:
        return False


def port_of_format(fmt: str) -> str:
    """The port of a recording that format *fmt* reads by default: the first (in the lab's
    order) that the host decodes as *fmt*, or whose own frames are *fmt*."""
    for p in ports.listed():
        if fmt in (p.format, p.frame_format):
            return p.name
    raise RecordingError(f"no port carries format {fmt!r}; name the recording's port to read")


def read_chunks(source: str, *, fmt: str = "sins", port: str | None = None, baud: int = DEFAULT_BAUD,
                follow: bool = False, idle: float = 1.0,
                stop: threading.Event | None = None) -> Iterator[bytes]:
    """Bytes from a file, ``-`` (stdin), a recording directory or a serial port / pyserial URL.

    A serial source without *follow* ends after *idle* seconds with no data; with *follow*
    it (and a growing file) is read until *stop* is set (checked at least every 50 ms).
    """
    stop = stop or threading.Event()
    if source == "-":
        stream = sys.stdin.buffer
        while chunk := stream.read1(CHUNK) if hasattr(stream, "read1") else stream.read(CHUNK):
            yield chunk
        return
    if _is_serial(source):
        import serial  # pyserial, only needed for live sources

        with serial.serial_for_url(source, baudrate=baud, timeout=0.05) as ser:
            last = time.monotonic()
            while not stop.is_set():
                chunk = ser.read(ser.in_waiting or 1)
                if chunk:
                    last = time.monotonic()
                    yield chunk
                elif not follow and time.monotonic() - last > idle:
                    return
    path = Path(source)
    if path.is_dir():
        rec = Recording(path)
        name = port or port_of_format(fmt)
        for c in rec.chunks(name):
            yield c.data
        return
    with open(path, "rb") as f:
        while not stop.is_set():
            chunk = f.read(CHUNK)
            if chunk:
                yield chunk
            elif follow:
                stop.wait(0.05)  # a growing file has no readiness to wait on
            else:
                return


def decode(source: str, fmt: str, *, escaped: bool = True, with_hex: bool = False,
           gyro_range: int = 300, **read_kw) -> Iterator[dict]:
    """Decode *source* as *fmt*: one dict per frame and per run of errors (:class:`ErrorRuns`;
    runs also end with each read, so a live port's errors are not held back), then
    ``{"summary": {...}}`` (which counts every error)."""
    dec = formats.get(fmt).make(escaped=escaped)
    runs = ErrorRuns()

    def records(events):
        for ev in events:
            if isinstance(ev, Frame):
                yield from runs.close()
                yield frame_record(ev, gyro_range=gyro_range, with_hex=with_hex)
            else:
                runs.add(ev)
        yield from runs.close()

    for chunk in read_chunks(source, fmt=fmt, **read_kw):
        yield from records(dec.feed(chunk))
    yield from records(dec.flush())
    yield {"summary": dec.summary()}
