"""Live control of a running emulation: a Unix socket in its private link directory.

A test breaks the lab at the moment it chooses (docs/emulator.md, "Live control")::

    DIR/control     AF_UNIX stream socket, mode 0600, in the 0700 link directory

Requests and replies are one JSON object per line (UTF-8, at most :data:`MAX_LINE` bytes).
A request names an ``op`` of :data:`OPS` and its arguments; every reply has ``ok``, and
either the op's result or ``error``, one line naming the problem and the fix::

    {"op": "fault", "fault": {"kind": "bit_errors", "port": "xbee", "ber": 1e-4}, "duration_s": 5}
    {"ok": true, "id": 1, "start_s": 12.34, "end_s": 17.34}

The emulation's loop serves the socket between writes, without blocking (a client that
stops reading loses its replies, never the lab's timing). The socket is the emulator's:
:class:`ControlServer` makes it, :class:`Control` is the client (``navtwin ctl`` and
``emulator.api.Lab``).
"""
from __future__ import annotations

import errno
import json
import os
import select
import socket
import time
from pathlib import Path
from typing import Callable

SOCKET = "control"  # its name in the link directory
MAX_LINE = 64 * 1024  # a request longer than this is refused, its connection closed
MAX_CLIENTS = 16
#: op -> what it does (the ``navtwin ctl`` help and the docs list these)
OPS = {
    "status": "the run: virtual time, ports (attached, plugged), live faults",
    "fault": "inject a fault now: {fault: {kind, ...settings}, duration_s?} (default: until cleared)",
    "clear": "end live faults: {id?} (default: all)",
    "unplug": "pull a port's cable: {port}; its link vanishes, clients read a hang-up",
    "replug": "plug it back: {port}; a new PTY behind the same link",
    "reset": "power-cycle a device now: {device: board|coordinator, duration_s?} (default 0.5 s)",
}


class ControlError(RuntimeError):
    """A request the lab refused, or no lab to ask; the message is one line with the fix."""


class ControlServer:
    """The listening socket and its connections; :meth:`serve` answers what has arrived."""

    def __init__(self, path: str | os.PathLike, handle: Callable[[dict], dict]) -> None:
        self.path = Path(path)
        self.handle = handle  # request -> result (ControlError for a refusal)
        try:
            self.path.unlink()  # a dead run's socket: the link directory's lock is ours
        except FileNotFoundError:
            pass
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_NONBLOCK
                                  | socket.SOCK_CLOEXEC)
        old = os.umask(0o177)  # 0600 from the start: no window where others could connect
        try:
            self.sock.bind(str(self.path))
        finally:
            os.umask(old)
        self.sock.listen(MAX_CLIENTS)
        self._clients: dict[socket.socket, bytearray] = {}
        self.requests = 0

    def fds(self) -> list:
        return [self.sock, *self._clients]

    def serve(self, readable=None) -> None:
        """Accept and answer without blocking; *readable*: what select said (None: poll)."""
        if readable is None:
            readable = select.select(self.fds(), [], [], 0)[0]
        for s in readable:
            if s is self.sock:
                self._accept()
            elif s in self._clients:
                self._read(s)

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            if len(self._clients) >= MAX_CLIENTS:
                conn.close()
                continue
            conn.setblocking(False)
            self._clients[conn] = bytearray()

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
        while b"\n" in buf:
            line, _, rest = bytes(buf).partition(b"\n")
            buf[:] = rest
            if not self._answer(conn, self._reply(line)):
                return
        if len(buf) > MAX_LINE:
            self._answer(conn, {"ok": False, "error": f"request longer than {MAX_LINE} bytes; "
                                                      "send one JSON object per line"})
            self._drop(conn)

    def _reply(self, line: bytes) -> dict:
        self.requests += 1
        try:
            req = json.loads(line)
        except (ValueError, UnicodeDecodeError) as e:
            return {"ok": False, "error": f"not JSON ({e}); send one JSON object per line"}
        if not isinstance(req, dict) or not isinstance(req.get("op"), str):
            return {"ok": False, "error": 'a request is an object with "op"; e.g. {"op": "status"}'}
        if req["op"] not in OPS:
            return {"ok": False, "error": f"unknown op {req['op']!r}; use one of {', '.join(OPS)}"}
        try:
            return {"ok": True, **self.handle(req)}
        except ControlError as e:
            return {"ok": False, "error": str(e)}

    def _answer(self, conn: socket.socket, reply: dict) -> bool:
        try:
            conn.sendall((json.dumps(reply, separators=(",", ":"), default=str) + "\n").encode())
            return True
        except OSError:  # full or gone: the client loses its reply, the lab its time never
            self._drop(conn)
            return False

    def _drop(self, conn: socket.socket) -> None:
        self._clients.pop(conn, None)
        conn.close()

    def close(self) -> None:
        for conn in list(self._clients):
            self._drop(conn)
        self.sock.close()
        try:
            self.path.unlink()
        except OSError:
            pass


class Control:
    """A client of a running lab's control socket (in its link directory *link_dir*)."""

    def __init__(self, link_dir: str | os.PathLike, timeout: float = 10.0) -> None:
        self.path = Path(link_dir) / SOCKET
        self.timeout = timeout
        self._sock: socket.socket | None = None
        self._buf = b""

    def _connect(self) -> socket.socket:
        if self._sock is None:
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
            s.settimeout(self.timeout)
            try:
                s.connect(str(self.path))
            except OSError as e:
                s.close()
                why = "no such socket" if e.errno in (errno.ENOENT, errno.ECONNREFUSED) else e.strerror
                raise ControlError(f"{self.path}: cannot connect ({why}); is an emulator running "
                                   "with this --link-dir?") from None
            self._sock = s
        return self._sock

    def call(self, op: str, **args) -> dict:
        """Send one request; its reply (ControlError if the lab refused it)."""
        s = self._connect()
        deadline = time.monotonic() + self.timeout
        try:
            s.sendall((json.dumps({"op": op, **args}) + "\n").encode())
            while b"\n" not in self._buf:
                s.settimeout(max(0.001, deadline - time.monotonic()))
                data = s.recv(65536)
                if not data:
                    raise ControlError(f"{self.path}: the emulator closed the connection; "
                                       "it has stopped")
                self._buf += data
        except (socket.timeout, TimeoutError):
            raise ControlError(f"{self.path}: no reply within {self.timeout:g} s; the emulator "
                               "is busy or stuck") from None
        except OSError as e:
            raise ControlError(f"{self.path}: {e.strerror or e}; the emulator has stopped") from None
        line, self._buf = self._buf.split(b"\n", 1)
        reply = json.loads(line)
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

    def reset(self, device: str, duration_s: float | None = None) -> dict:
        return self.call("reset", device=device, **({} if duration_s is None else
                                                    {"duration_s": duration_s}))

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> "Control":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
