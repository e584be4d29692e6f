"""Live control of a running emulation: a Unix socket in its private link directory.

A test breaks the lab at the moment it chooses (docs/emulator.md, "Live control")::

    DIR/control     AF_UNIX stream socket, mode 0600, in the 0700 link directory

Requests and replies are one JSON object per line (UTF-8, at most :data:`MAX_LINE` bytes).
A request names an ``op`` of :data:`OPS` and its arguments, checked against the op's
declared table (their types and ranges, as a scenario's keys are: common.schema); every
request gets a reply, with ``ok``, and either the op's result or ``error``, one line naming
the problem and the fix, whatever the request holds::

    {"op": "fault", "fault": {"kind": "bit_errors", "port": "xbee", "ber": 1e-4}, "duration_s": 5}
    {"ok": true, "id": 1, "start_s": 12.34, "end_s": 17.34}

The emulation's loop serves the socket between writes, without blocking (a client that
stops reading loses its replies, never the lab's timing). A connection that sends no
request for :data:`IDLE_TIMEOUT_S` is closed, and a client beyond :data:`MAX_CLIENTS` is
answered "busy", so idle clients cannot lock others out. The socket is the emulator's:
:class:`ControlServer` makes it, :class:`Control` is the client (``navtwin ctl`` and
``emulator.api.Lab``), one connection per request.
"""
from __future__ import annotations

import errno
import json
import os
import select
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from navtwin.common.limits import MAX_DURATION_S, VEHICLES, limit_problem
from navtwin.common.schema import REQUIRED, Invalid, between, build, key, positive

SOCKET = "control"  # its name in the link directory
MAX_LINE = 64 * 1024  # a request longer than this is refused, its connection closed
MAX_CLIENTS = 16
#: a connection with no request for this long is closed (a human at ``nc -U`` has a minute
#: between requests; a client that went quiet frees its place among MAX_CLIENTS)
IDLE_TIMEOUT_S = 60.0


class ControlError(RuntimeError):
    """A request the lab refused, or no lab to ask; the message is one line with the fix."""


# -- the requests: each op's arguments, declared once -------------------------------------
@dataclass(frozen=True)
class Status:
    """the run: virtual time, ports (attached, plugged), live faults, tap readers"""


@dataclass(frozen=True)
class Inject:
    """inject a fault now: {fault: {kind, ...settings}, duration_s?} (default: until cleared)"""

    fault: dict = key(REQUIRED, "", "the fault: a [[faults]] table without start_s/end_s")
    duration_s: float | None = key(None, "s", "how long it lasts; none = until cleared",
                                   positive(hi=MAX_DURATION_S))


@dataclass(frozen=True)
class Clear:
    """end live faults: {id?} (default: all)"""

    id: int | None = key(None, "", "the live fault to end (see status); none = all",
                         positive(hi=2**63 - 1))


@dataclass(frozen=True)
class Unplug:
    """pull a port's cable: {port}; its link vanishes, clients read a hang-up"""

    port: str = key(REQUIRED, "", "the port: sins, xbee or nanoloc (car n's: sins<n> ...)")


@dataclass(frozen=True)
class Replug(Unplug):
    """plug it back: {port}; a new PTY behind the same link"""


@dataclass(frozen=True)
class Reset:
    """power-cycle a device now: {device: board|coordinator, duration_s?, vehicle?} (default
    0.5 s, vehicle 1)"""

    device: str = key(REQUIRED, "", "the device: board or coordinator")
    duration_s: float | None = key(None, "s", "how long it is off; none = 0.5 s",
                                   positive(hi=MAX_DURATION_S))
    vehicle: int | None = key(None, "", "whose: the car's board, or its coordinator with a "
                              "coordinator per car; none = 1", between(*VEHICLES))


#: op -> its arguments (the class's docstring says what it does; ``navtwin ctl`` and the
#: docs list these)
OPS = {"status": Status, "fault": Inject, "clear": Clear, "unplug": Unplug, "replug": Replug,
       "reset": Reset}


def parse_request(line: bytes) -> tuple[str, object]:
    """(op, its arguments) of one request line; ControlError (one line) for anything else."""
    try:
        req = json.loads(line)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ControlError(f"not JSON ({e}); send one JSON object per line") from None
    except (ValueError, RecursionError) as e:  # json's limits: an integer's digits, nesting
        raise ControlError(f"{limit_problem(e)}; send a shorter request, e.g. "
                           '{"op": "status"}') from None
    op = req.get("op") if isinstance(req, dict) else None
    if not isinstance(op, str):
        raise ControlError('a request is an object with "op"; e.g. {"op": "status"}')
    if op not in OPS:
        raise ControlError(f"unknown op {op[:40]!r}; use one of {', '.join(OPS)}")
    try:
        return op, build(OPS[op], {k: v for k, v in req.items() if k != "op"})
    except Invalid as e:
        raise ControlError(f"{op}: {e}") from None


def private_listener(path: Path, backlog: int) -> socket.socket:
    """A non-blocking AF_UNIX listener at *path* in a lab's private link directory, mode 0600
    from the start (no window where others could connect); a dead run's socket there is
    replaced (the link directory's lock is ours)."""
    path.unlink(missing_ok=True)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_NONBLOCK
                         | socket.SOCK_CLOEXEC)
    old = os.umask(0o177)
    try:
        sock.bind(str(path))
    finally:
        os.umask(old)
    sock.listen(backlog)
    return sock


def close_listener(sock: socket.socket, path: Path) -> None:
    """Close a :func:`private_listener` and remove its path (gone already: fine)."""
    sock.close()
    try:
        path.unlink()
    except OSError:
        pass


class ControlServer:
    """The listening socket and its connections; :meth:`serve` answers what has arrived.

    *handle(op, args)* does a request (*args*: the op's table of :data:`OPS`) and gives its
    result, or raises ControlError to refuse it."""

    def __init__(self, path: str | os.PathLike, handle: Callable[[str, object], dict],
                 idle_timeout_s: float = IDLE_TIMEOUT_S) -> None:
        self.path = Path(path)
        self.handle = handle
        self.idle_timeout_s = idle_timeout_s
        self.sock = private_listener(self.path, MAX_CLIENTS)
        self._clients: dict[socket.socket, bytearray] = {}
        self._idle_since: dict[socket.socket, float] = {}  # the last request, or the accept
        self.requests = 0

    def fds(self) -> list:
        return [self.sock, *self._clients]

    def serve(self, readable=None) -> None:
        """Accept and answer without blocking; *readable*: what select said (None: poll).
        Connections idle for longer than the timeout are closed."""
        if readable is None:
            readable = select.select(self.fds(), [], [], 0)[0]
        for s in readable:
            if s is self.sock:
                self._accept()
            elif s in self._clients:
                self._read(s)
        stale = time.monotonic() - self.idle_timeout_s
        for conn in [c for c, t in self._idle_since.items() if t < stale]:
            self._drop(conn)

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            conn.setblocking(False)
            if len(self._clients) >= MAX_CLIENTS:  # told why, so it can try again later
                self._answer(conn, {"ok": False, "error": f"busy: {MAX_CLIENTS} clients are "
                                    f"connected (each closed after {self.idle_timeout_s:g} s "
                                    "idle); try again later"})
                conn.close()
                continue
            self._clients[conn] = bytearray()
            self._idle_since[conn] = time.monotonic()

    def _read(self, conn: socket.socket) -> None:
        buf = self._clients[conn]
        try:
            data = conn.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(conn)
            return
        buf += data
        if b"\n" in buf:
            *lines, rest = bytes(buf).split(b"\n")
            buf[:] = rest
            self._idle_since[conn] = time.monotonic()
            for line in lines:
                if not self._answer(conn, self._reply(line)):
                    return
        if len(buf) > MAX_LINE:
            self._answer(conn, {"ok": False, "error": f"request longer than {MAX_LINE} bytes; "
                                                      "send one JSON object per line"})
            self._drop(conn)

    def _reply(self, line: bytes) -> dict:
        self.requests += 1
        try:
            return {"ok": True, **self.handle(*parse_request(line))}
        except ControlError as e:
            return {"ok": False, "error": str(e)}

    def _answer(self, conn: socket.socket, reply: dict) -> bool:
        """Send *reply* on *conn*; False (and *conn* dropped) if it could not be."""
        try:
            conn.sendall((json.dumps(reply, separators=(",", ":"), default=str) + "\n").encode())
            return True
        except OSError:  # full or gone: the client loses its reply, the lab its time never
            self._drop(conn)
            return False

    def _drop(self, conn: socket.socket) -> None:
        self._clients.pop(conn, None)
        self._idle_since.pop(conn, None)
        conn.close()

    def close(self) -> None:
        for conn in list(self._clients):
            self._drop(conn)
        close_listener(self.sock, self.path)


class Control:
    """A client of a running lab's control socket (in its link directory *link_dir*): one
    connection per request, so it holds no place among the lab's clients between them."""

    def __init__(self, link_dir: str | os.PathLike, timeout: float = 10.0) -> None:
        self.path = Path(link_dir) / SOCKET
        self.timeout = timeout

    def _connect(self) -> socket.socket:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        s.settimeout(self.timeout)
        try:
            s.connect(str(self.path))
        except OSError as e:
            s.close()
            why = "no such socket" if e.errno in (errno.ENOENT, errno.ECONNREFUSED) else e.strerror
            raise ControlError(f"link_dir: {self.path}: cannot connect ({why}); is an emulator "
                               "running on this link directory?") from None
        return s

    def call(self, op: str, **args) -> dict:
        """Send one request; its reply (ControlError if the lab refused it or is busy)."""
        deadline = time.monotonic() + self.timeout
        buf = b""
        with self._connect() as s:
            try:
                try:
                    s.sendall((json.dumps({"op": op, **args}) + "\n").encode())
                except (BrokenPipeError, ConnectionResetError):
                    pass  # a full lab answers "busy" and closes unread: its reply is below
                while b"\n" not in buf:
                    s.settimeout(max(0.001, deadline - time.monotonic()))
                    data = s.recv(65536)
                    if not data:
                        raise ControlError(f"{self.path}: the emulator closed the connection; "
                                           "it has stopped")
                    buf += data
            except (socket.timeout, TimeoutError):
                raise ControlError(f"{self.path}: no reply within {self.timeout:g} s; the "
                                   "emulator is busy or stuck") from None
            except OSError as e:
                raise ControlError(f"{self.path}: {e.strerror or e}; the emulator has "
                                   "stopped") from None
        reply = json.loads(buf.split(b"\n", 1)[0])
        if not reply.get("ok"):
            raise ControlError(reply.get("error", "refused"))
        return reply

    # the lab's words, for tests
    def status(self) -> dict:
        return self.call("status")

    def fault(self, kind: str, duration_s: float | None = None, **settings) -> dict:
        """Inject a fault of *kind* now, for *duration_s* (None: until :meth:`clear`)."""
        args = {} if duration_s is None else {"duration_s": duration_s}
        return self.call("fault", fault={"kind": kind, **settings}, **args)

    def clear(self, id: int | None = None) -> dict:
        return self.call("clear", **({} if id is None else {"id": id}))

    def unplug(self, port: str) -> dict:
        return self.call("unplug", port=port)

    def replug(self, port: str) -> dict:
        return self.call("replug", port=port)

    def reset(self, device: str, duration_s: float | None = None, vehicle: int | None = None) -> dict:
        return self.call("reset", device=device, **({} if vehicle is None else {"vehicle": vehicle}),
                         **({} if duration_s is None else {"duration_s": duration_s}))
