"""RFC 2217 (Telnet COM-PORT-OPTION) servers: every port of the lab on a TCP port of its own.

Why a client of the PTY, not a hook into the runner: each connection opens the port's
link (the PTY slave) exactly as a local client would and programs the slave's termios from
what the TCP client sets. The emulator then sees that client as it sees any other: attach
and detach (POLLHUP), stale-byte flushes, unplug and replug (a new connection follows the
link to the new ``/dev/pts/N``), and the client's line settings read by
:meth:`PtyPort.client_framing` into the device's UART model (emulator.uart_rx). So a client
that sets 9600 baud reads the same garbage as a local one at 9600, from the same code, and
the runner is untouched (no bytes of a run without ``--rfc2217`` change).

Protocol (RFC 854/856/858, RFC 2217), per connection:

* Telnet: the server offers WILL/DO BINARY, SGA and COM-PORT-OPTION and agrees to the
  client's requests for those three, refusing every other option (WONT/DONT); each answer is
  sent once per option and direction, so negotiation cannot loop. Data 0xFF is doubled
  (IAC IAC) towards the client and undoubled from it; CR is never altered (binary mode).
* COM-PORT-OPTION requests (client codes 1..12) are answered with the server codes
  (+100) carrying the value now in force: SET-BAUDRATE (0: query), SET-DATASIZE,
  SET-PARITY, SET-STOPSIZE (0: query) become the slave's ``c_cflag`` and speed. The PTY
  driver forces CS8 and clears PARENB (emulator.pty), so of these the device sees the baud
  and the stop bits, as for a local client; the server still echoes what the client asked,
  as a client such as pyserial checks it. A rate that is no termios B constant is refused
  by answering the rate in force.
* SET-CONTROL: flow control (XON/XOFF, RTS/CTS), DTR, RTS and break on/off are acknowledged
  and remembered (queries answer them); a PTY has no modem lines and the lab's devices use
  none, so they change nothing on the line. PURGE-DATA flushes the slave's queues
  (1: received from the device, 2: towards the device, 3: both). NOTIFY-LINESTATE and
  NOTIFY-MODEMSTATE are never sent (masks acknowledged): no line has a state to tell.

A client's settings last as long as its connection: the port's termios are put back as
they were when it closes, so the next client (TCP or local) does not inherit a 9600.

One client per port at a time: a second connection is closed at once, as a serial port
held open by one program is busy for another.
"""
from __future__ import annotations

import os
import select
import socket
import termios
import threading
import tty
from pathlib import Path

from .pty import SPEED_BAUD  # the table the port reads the client's rate with
from .uart_rx import CSIZE_BITS  # and the one it reads the data bits with

IAC, DONT, DO, WONT, WILL, SB, SE = 255, 254, 253, 252, 251, 250, 240
BINARY, SGA, COM_PORT = 0, 3, 44
AGREED = (BINARY, SGA, COM_PORT)  # the options this server takes, both ways
SERVER = 100  # a server's reply code is the client's request code plus this
SET_BAUDRATE, SET_DATASIZE, SET_PARITY, SET_STOPSIZE, SET_CONTROL = 1, 2, 3, 4, 5
SET_LINESTATE_MASK, SET_MODEMSTATE_MASK, PURGE_DATA = 10, 11, 12
#: SET-CONTROL: request code -> (setting it asks about, value in force at connect)
CONTROL_QUERIES = {0: ("flow", 1), 4: ("break", 6), 7: ("dtr", 8), 10: ("rts", 11),
                   13: ("inflow", 14)}
#: SET-CONTROL: set code -> the setting it changes
CONTROL_SETS = {**{v: "flow" for v in (1, 2, 3, 17, 18, 19)}, 5: "break", 6: "break",
                8: "dtr", 9: "dtr", 11: "rts", 12: "rts",
                **{v: "inflow" for v in (14, 15, 16)}}
CSIZES = {bits: flag for flag, bits in CSIZE_BITS.items()}  # data bits -> c_cflag CSIZE
#: RFC 2217 parity codes -> c_cflag bits (MARK and SPACE: stick parity, kept as asked)
PARITY_FLAGS = {1: 0, 2: termios.PARENB | termios.PARODD, 3: termios.PARENB,
                4: termios.PARENB | termios.PARODD, 5: termios.PARENB}
PURGES = {1: termios.TCIFLUSH, 2: termios.TCOFLUSH, 3: termios.TCIOFLUSH}
CHUNK = 4096


class Rfc2217Error(ValueError):
    """An RFC 2217 address that cannot be served; one line naming the fix."""


def parse_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, first TCP port); loopback unless a host is given."""
    host, colon, port = text.rpartition(":")
    host = host.strip("[]") if colon else "127.0.0.1"
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise Rfc2217Error(f"rfc2217: {text!r}: write [HOST:]PORT with PORT a TCP port 1-65535")
    return host or "127.0.0.1", int(port)


class Rfc2217Servers:
    """One listening TCP port per serial port, from *first* on in the order of *links*
    (name -> link path); :attr:`urls` for the ready line. Serves until :meth:`close`."""

    def __init__(self, links: dict[str, str], host: str, first: int) -> None:
        self._listeners: list[socket.socket] = []
        self._stop = threading.Event()
        self.urls: dict[str, str] = {}
        try:
            for i, (name, link) in enumerate(links.items()):
                if first + i > 65535:
                    raise Rfc2217Error(f"rfc2217: {len(links)} ports from {first} pass 65535; "
                                       "choose a lower first PORT")
                sock = self._listen(host, first + i)
                self._listeners.append(sock)
                shown = f"[{host}]" if ":" in host else host
                self.urls[name] = f"rfc2217://{shown}:{first + i}"
                threading.Thread(target=self._accept, args=(sock, Path(link)), daemon=True,
                                 name=f"rfc2217-{name}").start()
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _listen(host: str, port: int) -> socket.socket:
        try:
            family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
            sock = socket.socket(family, socket.SOCK_STREAM)
        except OSError as e:
            raise Rfc2217Error(f"rfc2217: {host}: {e.strerror or e}; give an address of "
                               "this machine") from None
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
            sock.listen(1)
        except OSError as e:
            sock.close()
            raise Rfc2217Error(f"rfc2217: {host}:{port}: {e.strerror}; choose other TCP "
                               "ports (one per serial port from the first)") from None
        return sock

    def _accept(self, sock: socket.socket, link: Path) -> None:
        busy = threading.Lock()
        while not self._stop.is_set():
            try:
                conn, _ = sock.accept()
            except OSError:
                return  # closed
            if not busy.acquire(blocking=False):
                conn.close()  # the port is held by another client
                continue

            def serve(conn=conn):
                try:
                    Session(conn, link, self._stop).run()
                finally:
                    busy.release()
            threading.Thread(target=serve, daemon=True).start()

    def close(self) -> None:
        self._stop.set()
        for sock in self._listeners:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()
        self._listeners.clear()


class Session:
    """One TCP client on one port's PTY: the Telnet parser and the two byte pumps."""

    def __init__(self, conn: socket.socket, link: Path, stop: threading.Event) -> None:
        self.conn, self.link, self.stop = conn, link, stop
        self.fd = -1
        self.sent: set[tuple[int, int]] = set()  # (verb, option) answers already sent
        self.control = {key: value for key, value in CONTROL_QUERIES.values()}
        self.asked: dict[int, bytes] = {}  # datasize/parity/stopsize as the client set them
        self._state = "data"
        self._sb = bytearray()

    def run(self) -> None:
        try:
            self.fd = os.open(self.link, os.O_RDWR | os.O_NOCTTY | os.O_CLOEXEC)
        except OSError:
            self.conn.close()  # unplugged: no device node, as for a local client
            return
        try:
            before = termios.tcgetattr(self.fd)
            tty.setraw(self.fd)
            self._offer()
            self._pump()
            termios.tcsetattr(self.fd, termios.TCSANOW, before)
        except (OSError, termios.error):
            pass  # the client or the port went away (a hung-up PTY: termios.error)
        finally:
            os.close(self.fd)
            self.conn.close()

    def _offer(self) -> None:
        for option in AGREED:
            self._negotiate(WILL, option)
            self._negotiate(DO, option)

    def _negotiate(self, verb: int, option: int) -> None:
        if (verb, option) not in self.sent:
            self.sent.add((verb, option))
            self.conn.sendall(bytes((IAC, verb, option)))

    def _pump(self) -> None:
        sock = self.conn.fileno()
        while not self.stop.is_set():
            ready, _, _ = select.select([sock, self.fd], [], [], 0.2)
            if self.fd in ready:
                data = os.read(self.fd, CHUNK)
                if not data:
                    return
                self.conn.sendall(data.replace(b"\xff", b"\xff\xff"))
            if sock in ready:
                data = self.conn.recv(CHUNK)
                if not data:
                    return
                out = self._telnet(data)
                if out:
                    os.write(self.fd, out)

    def _telnet(self, data: bytes) -> bytes:
        """The client's data bytes of *data*; commands handled on the way."""
        out = bytearray()
        for b in data:
            state = self._state
            if state == "data":
                if b == IAC:
                    self._state = "iac"
                else:
                    out.append(b)
            elif state == "iac":
                if b == IAC:
                    out.append(b)
                    self._state = "data"
                elif b in (DO, DONT, WILL, WONT):
                    self._state = b
                elif b == SB:
                    self._sb.clear()
                    self._state = "sb"
                else:
                    self._state = "data"  # NOP, AYT, ...: nothing to do on a serial line
            elif state == "sb":
                if b == IAC:
                    self._state = "sb-iac"
                else:
                    self._sb.append(b)
            elif state == "sb-iac":
                if b == SE:
                    self._subnegotiation(bytes(self._sb))
                    self._state = "data"
                else:
                    self._sb.append(b)  # IAC IAC: a data 0xFF inside the value
                    self._state = "sb"
            else:  # the option of a DO/DONT/WILL/WONT
                self._option(state, b)
                self._state = "data"
        return bytes(out)

    def _option(self, verb: int, option: int) -> None:
        agreed = option in AGREED
        if verb == WILL:
            self._negotiate(DO if agreed else DONT, option)
        elif verb == DO:
            self._negotiate(WILL if agreed else WONT, option)
        # WONT/DONT: the client declines; a serial line needs nothing of those options

    def _reply(self, code: int, value: bytes) -> None:
        body = bytes((COM_PORT, code + SERVER)) + value
        self.conn.sendall(bytes((IAC, SB)) + body.replace(b"\xff", b"\xff\xff")
                          + bytes((IAC, SE)))

    def _subnegotiation(self, sb: bytes) -> None:
        if len(sb) < 2 or sb[0] != COM_PORT:
            return
        code, value = sb[1], sb[2:]
        if code == SET_BAUDRATE and len(value) == 4:
            self._reply(code, self._baud(int.from_bytes(value, "big")).to_bytes(4, "big"))
        elif code in (SET_DATASIZE, SET_PARITY, SET_STOPSIZE) and len(value) == 1:
            self._reply(code, self._framing(code, value))
        elif code == SET_CONTROL and len(value) == 1:
            self._reply(code, bytes((self._control(value[0]),)))
        elif code == PURGE_DATA and len(value) == 1:
            if value[0] in PURGES:
                termios.tcflush(self.fd, PURGES[value[0]])
            self._reply(code, value)
        elif code in (SET_LINESTATE_MASK, SET_MODEMSTATE_MASK):
            self._reply(code, value)
        # FLOWCONTROL-SUSPEND/RESUME and NOTIFY-*: the server never stops the line

    def _baud(self, baud: int) -> int:
        """Set the slave's speed to *baud* (0: only ask); the rate now in force."""
        attrs = termios.tcgetattr(self.fd)
        speed = getattr(termios, f"B{baud}", None) if baud else None
        if speed is not None:
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(self.fd, termios.TCSANOW, attrs)
            return baud
        return SPEED_BAUD.get(attrs[5], 0)

    def _framing(self, code: int, value: bytes) -> bytes:
        """SET-DATASIZE/PARITY/STOPSIZE into ``c_cflag``; 0 asks for the value in force."""
        v = value[0]
        if v == 0:
            return self.asked.get(code, value)
        attrs = termios.tcgetattr(self.fd)
        if code == SET_DATASIZE and v in CSIZES:
            attrs[2] = attrs[2] & ~termios.CSIZE | CSIZES[v]
        elif code == SET_PARITY and v in PARITY_FLAGS:
            attrs[2] = attrs[2] & ~(termios.PARENB | termios.PARODD) | PARITY_FLAGS[v]
        elif code == SET_STOPSIZE and v in (1, 2, 3):  # 3: 1.5 bits, two on a UART's register
            attrs[2] = attrs[2] & ~termios.CSTOPB | (termios.CSTOPB if v != 1 else 0)
        else:
            return self.asked.get(code, bytes(1))
        termios.tcsetattr(self.fd, termios.TCSANOW, attrs)
        self.asked[code] = value
        return value

    def _control(self, v: int) -> int:
        if v in CONTROL_QUERIES:
            return self.control[CONTROL_QUERIES[v][0]]
        if v in CONTROL_SETS:
            self.control[CONTROL_SETS[v]] = v
        return v
