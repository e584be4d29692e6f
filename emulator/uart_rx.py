"""What a client's UART reads from a line sent at other settings: the bit-level receiver.

A PTY has no UART: the kernel hands the client every byte the emulator writes, whatever
baud, parity or data bits the client asked for. On the lab's hardware a host at the wrong
settings reads garbage. :class:`Receiver` computes that garbage from the waveform the
device's UART puts on the line, and :func:`tty_bytes` what Linux then delivers; the port
(emulator.pty) writes the result instead of the device's bytes while the client's
settings differ (:class:`ClientView`).

The line (transmitter at ``tx``): idle high; each byte is a start bit (low), the data bits
LSB first, the parity bit if any, the stop bits (high); the bytes of a chunk back to back,
the line idle between chunks (``Chunk.start_ns``; a chunk lasts ``wire_ns``).

The receiver (at ``rx``), as a 16550 does: it waits for a falling edge, samples the middle
of each of its own bit times from there (start, data, parity, first stop bit), and:

* a start bit read high in its middle was a glitch: it hunts again from that instant;
* a stop bit read low is a framing error; every sample low (start to stop) is a break
  (the 16550's BI, which the 8250 driver reports instead of the framing error);
* it checks only the first stop bit (16550: "the receiver checks the first stop bit only"),
  so stop bits alone never garble: 8N2 reads 8N1 cleanly and the other way round;
* after the stop sample it hunts for the next falling edge; a line still low there must go
  high first (one break character per low period).

Edges are taken exactly, at the transmitter's bit boundaries; a sample on an edge reads the
new bit (a real receiver detects the start edge up to 1/16 bit late, so its samples fall
just after the nominal instants). Positions are in transmitter bit times from the chunk's
start, where every edge is an integer, so ties are exact for the usual rate ratios.

State carries across chunks: a frame whose samples reach past the end of the chunk is
finished when a later chunk shows what the line did there (idle high between chunks), so
its byte is delivered with that later chunk. No randomness: the same chunks give the same
bytes.
"""
from __future__ import annotations

import functools
import termios
from dataclasses import dataclass

import numpy as np

SEC = 1_000_000_000
EPS = 1e-9  # in bit times: a sample a rounding error before an edge reads the new bit
PARITIES = ("N", "E", "O")
CSIZE_BITS = {termios.CS5: 5, termios.CS6: 6, termios.CS7: 7, termios.CS8: 8}


@dataclass(frozen=True, slots=True)
class Framing:
    """A UART's settings: baud, data bits (5-8), parity (N, E, O), stop bits (1, 2)."""

    baud: int
    bits: int = 8
    parity: str = "N"
    stop: int = 1

    def __str__(self) -> str:
        return f"{self.baud} {self.bits}{self.parity}{self.stop}"

    @classmethod
    def from_cflag(cls, baud: int, cflag: int) -> "Framing":
        """The framing a UART takes from a termios ``c_cflag``, as the 8250 driver programs
        its line control register (serial8250_do_set_termios): PARODD (and CMSPAR's stick
        parity, not modelled) mean something only under PARENB, so a PARODD a previous
        client left behind, or ``cfmakeraw`` kept, is no parity; CSIZE and CSTOPB count
        as set, whoever set them."""
        parity = ("O" if cflag & termios.PARODD else "E") if cflag & termios.PARENB else "N"
        return cls(baud, CSIZE_BITS[cflag & termios.CSIZE], parity,
                   2 if cflag & termios.CSTOPB else 1)

    @property
    def frame_bits(self) -> int:
        return 1 + self.bits + (self.parity != "N") + self.stop

    def garbles(self, other: "Framing") -> bool:
        """Whether a receiver at *other* reads anything but what this transmitter sent
        (stop bits do not count: a receiver checks the first one only)."""
        return (self.baud, self.bits, self.parity) != (other.baud, other.bits, other.parity)


@functools.cache
def line_framing(baud: int) -> Framing:
    """A device's line at *baud* (8N1), one object per rate: the write path compares a
    chunk's with its port's by identity first (:meth:`ClientView.view`), at every write."""
    return Framing(baud)


def waveform(data: bytes, tx: Framing) -> np.ndarray:
    """The line levels (uint8, one per transmitter bit time) of *data* sent back to back."""
    d = np.frombuffer(data, dtype=np.uint8)
    bits = np.unpackbits(d[:, None], axis=1, bitorder="little")[:, :tx.bits]
    cols = [np.zeros((len(d), 1), np.uint8), bits]
    if tx.parity != "N":
        odd = bits.sum(axis=1, dtype=np.uint8) & 1
        cols.append((odd ^ (tx.parity == "O"))[:, None].astype(np.uint8))
    cols.append(np.ones((len(d), tx.stop), np.uint8))
    return np.concatenate(cols, axis=1).ravel()


@dataclass(slots=True)
class Received:
    """What the receiver read: a value per character and its error flags (numpy arrays)."""

    values: np.ndarray
    framing: np.ndarray
    parity: np.ndarray
    breaks: np.ndarray

    @classmethod
    def join(cls, parts: list["Received"]) -> "Received":
        if not parts:
            return cls(*(np.zeros(0, t) for t in (np.uint8, bool, bool, bool)))
        return cls(*(np.concatenate([getattr(p, f) for p in parts])
                     for f in ("values", "framing", "parity", "breaks")))


class Receiver:
    """A UART at ``rx`` listening to a transmitter at ``tx`` (module docstring)."""

    def __init__(self, tx: Framing, rx: Framing) -> None:
        self.tx, self.rx = tx, rx
        self.r = tx.baud / rx.baud  # one receiver bit time, in transmitter bit times
        self.stop_at = 1 + rx.bits + (rx.parity != "N")  # index of the (first) stop sample
        self.offsets = (np.arange(self.stop_at + 1) + 0.5) * self.r
        # a frame whose samples reach past the last chunk: the chunks it may read from,
        # (start_ns, levels), the first being the one holding its start edge at ``_edge``
        self._segments: list[tuple[int, np.ndarray]] = []
        self._edge = 0

    def feed(self, start_ns: int, data: bytes) -> Received:
        """The characters completed by a chunk of *data* whose first bit starts at *start_ns*
        (an empty chunk says the line was idle until then: it finishes a pending frame)."""
        levels = waveform(data, self.tx)
        out = []
        hunt = -1.0  # the next frame starts at the first falling edge after this position
        if self._segments:
            self._segments.append((start_ns, levels))
            done = self._finish_pending(start_ns, len(levels))
            if done is None:
                return Received.join([])
            hunt, frame = done
            self._segments.clear()
            if frame is not None:
                out.append(frame)
        out.append(self._frames(start_ns, levels, hunt))
        return Received.join(out)

    def _at(self, pos: float) -> int:
        """Line level at *pos* (transmitter bit times from the pending frame's chunk)."""
        s0 = self._segments[0][0]
        for s, lv in self._segments:
            p = pos - (s - s0) * self.tx.baud / SEC
            i = int(np.floor(p + EPS))
            if 0 <= i < len(lv):
                return int(lv[i])
        return 1  # idle between chunks

    def _finish_pending(self, start_ns: int, n: int):
        """(hunt position in this chunk, the frame or None) once the line is known far
        enough, else None."""
        s0 = self._segments[0][0]
        shift = (start_ns - s0) * self.tx.baud / SEC  # this chunk's start, in the first's bits
        end = shift + n
        pos = self._edge + self.offsets
        if pos[0] + EPS >= end:
            return None
        if self._at(pos[0]):  # a glitch, not a start bit
            return pos[0] - shift, None
        if pos[-1] + EPS >= end:
            return None
        lv = np.array([self._at(p) for p in pos], np.uint8)[None, :]
        return pos[-1] - shift, self._decode(lv)

    def _frames(self, start_ns: int, levels: np.ndarray, hunt: float) -> Received:
        n = len(levels)
        fall = np.flatnonzero(np.diff(levels, prepend=np.uint8(1)).view(np.int8) == -1)
        centre = np.floor(fall + self.offsets[0] + EPS).astype(np.int64)
        stop = np.floor(fall + self.offsets[-1] + EPS).astype(np.int64)
        inside = centre < n
        started = np.zeros(len(fall), bool)
        started[inside] = levels[centre[inside]] == 0
        after = np.where(started, fall + self.offsets[-1], fall + self.offsets[0])
        following = np.searchsorted(fall, after + EPS, side="right").tolist()
        centre_in, started_l, stop_in = inside.tolist(), started.tolist(), (stop < n).tolist()
        chosen = []
        i = int(np.searchsorted(fall, hunt + EPS, side="right"))
        while i < len(fall):  # the only sequential part: which edges start a frame
            if not centre_in[i] or (started_l[i] and not stop_in[i]):
                self._segments = [(start_ns, levels)]
                self._edge = int(fall[i])
                break
            if started_l[i]:
                chosen.append(i)
            i = following[i]
        idx = np.floor(fall[chosen][:, None] + self.offsets[None, :] + EPS).astype(np.int64)
        return self._decode(levels[idx])

    def _decode(self, lv: np.ndarray) -> Received:
        """Characters from their samples (rows: start, data..., parity, stop)."""
        rx = self.rx
        data = lv[:, 1:1 + rx.bits]
        values = (data.astype(np.uint16) << np.arange(rx.bits, dtype=np.uint16)).sum(
            axis=1).astype(np.uint8)
        brk = ~lv.any(axis=1)
        framing = (lv[:, self.stop_at] == 0) & ~brk
        if rx.parity == "N":
            parity = np.zeros(len(lv), bool)
        else:
            ones = data.sum(axis=1) + lv[:, 1 + rx.bits]
            parity = ((ones & 1) == (rx.parity == "E")) & ~brk
        return Received(values, framing, parity, brk)


def tty_bytes(rec: Received, iflag: int) -> bytes:
    """What Linux gives a reader of a serial tty for *rec*, by the client's c_iflag.

    The 8250 driver (drivers/tty/serial/8250/8250_port.c, serial8250_read_char and
    serial8250_do_set_termios) reports parity and framing errors only under INPCK and a
    break only under IGNBRK, BRKINT or PARMRK; otherwise the character is delivered as
    read (a break reads 0x00). Under INPCK, IGNPAR drops a character in error. n_tty
    (drivers/tty/n_tty.c, n_tty_receive_parity_error and n_tty_receive_break) then gives
    ``\\xff\\x00 c`` for an error under PARMRK, else ``\\x00``; a break is dropped under
    IGNBRK, raises SIGINT under BRKINT (not emulated: the character is dropped), is
    ``\\xff\\x00\\x00`` under PARMRK, else ``\\x00``. Everything else n_tty does to normal
    characters (ISTRIP, ICRNL, PARMRK's doubling of 0xff) the PTY's own n_tty does to what
    the emulator writes: so under PARMRK a mark's 0xff arrives doubled.
    """
    values = rec.values
    inpck = bool(iflag & termios.INPCK)
    errs = (rec.framing | rec.parity) if inpck else np.zeros(len(values), bool)
    brk = rec.breaks if iflag & (termios.IGNBRK | termios.BRKINT | termios.PARMRK) else \
        np.zeros(len(values), bool)
    if not errs.any() and not brk.any():
        return values.tobytes()
    out = bytearray()
    parmrk = bool(iflag & termios.PARMRK)
    for c, e, b in zip(values.tolist(), errs.tolist(), brk.tolist()):
        if b:
            if not iflag & (termios.IGNBRK | termios.BRKINT):
                out += b"\xff\x00\x00" if parmrk else b"\x00"
        elif e:
            if not iflag & termios.IGNPAR:
                out += bytes((0xFF, 0, c)) if parmrk else b"\x00"
        else:
            out.append(c)
    return bytes(out)


class ClientView:
    """One port's client as its UART would read the device, and the device's UART the
    client (:meth:`heard`): while the client's settings garble the device's line the port
    gives it :class:`Receiver`'s characters through :func:`tty_bytes`, and counts them.
    *notify* gets one line when the client starts or stops differing from the device
    (settings, or the device's rate, e.g. the XBee's BD)."""

    def __init__(self, port: str, device: Framing, notify=None) -> None:
        self.port = port
        self.device = device
        self.notify = notify or (lambda line: None)
        self.seen: Framing | None = None  # the client's settings; None: no client
        self.iflag = 0
        self.receiver: Receiver | None = None
        self.events: list[str] = []
        self._key: tuple | None = None  # (client, device) while they differ
        self.chars = 0  # characters the client's UART read while garbled
        self.framing_errors = self.parity_errors = self.breaks = 0
        self.garbled_bytes = 0  # device bytes sent while the client read them garbled
        self.listener: Receiver | None = None  # the device's UART reading the client's bytes
        self._heard_until = 0  # ns: when the client's last byte had left its UART
        self.garbled_host_bytes = 0  # client bytes the device read garbled

    @property
    def client(self) -> Framing | None:
        """The client's settings while they differ from the device's, else None."""
        return self.seen if self.seen is not None and self.seen != self.device else None

    def settle(self, seen: Framing | None, iflag: int, device: Framing | None = None) -> None:
        """Take the client's settings as read from its termios (None: detached)."""
        if device is None and seen is self.seen and iflag == self.iflag:
            return  # as before (the port gives the same objects): nothing changes
        before = self.client
        self.seen, self.iflag = seen, iflag
        self.device = device or self.device
        now = self.client
        if now is None or not self.device.garbles(now):
            self.receiver = None
        elif self.receiver is None or (self.receiver.tx, self.receiver.rx) != (self.device, now):
            self.receiver = Receiver(self.device, now)
        key = None if now is None else (now, self.device)
        if key == self._key:
            return
        self._key = key
        if now is not None:
            line = self.status(counts=False)
        elif seen is None:
            line = f"{self.port}: client gone (it was at {before}, device {self.device})"
        else:
            line = f"{self.port}: client at the device's settings ({self.device}) again"
        self.events.append(line)
        self.notify(line)

    def status(self, counts: bool = True) -> str:
        """One line while the client differs from the device, else ""; *counts*: with the
        run's totals so far."""
        client = self.client
        if client is None:
            return ""
        if self.receiver is None:
            reads = "the client reads clean bytes (a UART checks the first stop bit only)"
        else:
            reads = "the client reads garbage" + (
                f" ({self.garbled_bytes} bytes garbled so far, {self.framing_errors} framing "
                f"errors, {self.parity_errors} parity errors)" if counts else "")
        return f"{self.port}: client at {client}, device {self.device}: {reads}"

    def view(self, start_ns: int, data: bytes, device: Framing) -> bytes:
        """The bytes to give the client for a chunk the device sent at *device*."""
        if device is not self.device and device != self.device:  # the device's BD changed
            self.settle(self.seen, self.iflag, device)
        if self.receiver is None:
            return data
        rec = self.receiver.feed(start_ns, data)
        self.chars += len(rec.values)
        self.framing_errors += int(rec.framing.sum())
        self.parity_errors += int(rec.parity.sum())
        self.breaks += int(rec.breaks.sum())
        self.garbled_bytes += len(data)
        return tty_bytes(rec, self.iflag)

    def heard(self, t_ns: int, data: bytes, device: Framing) -> bytes:
        """What the device's UART at *device* reads from bytes the client wrote that reach
        it at *t_ns*: the same receiver and rule (:meth:`Framing.garbles`) the other way,
        the bytes sent back to back at the client's settings (after any sent before)."""
        client = self.seen
        if client is None or not client.garbles(device):
            self.listener = None
            return data
        if self.listener is None or (self.listener.tx, self.listener.rx) != (client, device):
            self.listener = Receiver(client, device)
        wire = len(data) * client.frame_bits * SEC // client.baud
        start = max(t_ns - wire, self._heard_until)
        self._heard_until = start + wire
        self.garbled_host_bytes += len(data)
        # a UART's errors and breaks reach no tty here: the device's firmware gets the values
        return self.listener.feed(start, data).values.tobytes()

    def stats(self) -> dict:
        return {"client": str(self.seen) if self.seen else None, "device": str(self.device),
                "garbled_bytes": self.garbled_bytes,
                "garbled_host_bytes": self.garbled_host_bytes, "client_chars": self.chars,
                "framing_errors": self.framing_errors, "parity_errors": self.parity_errors,
                "breaks": self.breaks}
