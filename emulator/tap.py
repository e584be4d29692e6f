"""A live tap on a running lab: every chunk of every port as it is delivered, on a Unix socket
in the lab's private link directory (docs/emulator.md, "The tap")::

    DIR/tap     AF_UNIX stream socket, mode 0600, in the 0700 link directory

A client connects and reads; it sends nothing. It gets first a hello, one JSON line::

    {"format": "navtwin-tap", "version": 1, "scenario": "office", "seed": 7, "speed": "max",
     "duration_s": 60.0, "ports": {"sins": {"baud": 115200, ...}, ...},
     "offsets": {"sins": 10240, ...}, "streams": {"air": {"linktype": 195, "doc": "..."}}}

``ports`` are the ports' settings as a recording's meta has them; ``offsets`` how many bytes
of each port were delivered before this client came (so its bytes are the recording's
``<port>.bin`` from that offset on); ``streams`` the streams that are not ports, declared so
far (the radio's air), with their pcapng link type. Then records, each a header and its
name and data, little-endian::

    offset size  field
    0      1     kind          0 to_host (a device's bytes, as the recording keeps them),
                               1 to_device (what the host wrote to the port),
                               2 stream (a packet of a stream that is not a port),
                               3 declare (a stream from now on: data is JSON {linktype, doc}),
                               4 end (the run is over: nothing follows; name and data empty)
    1      1     name_len      the port's or stream's name, UTF-8, after the header
    2      2     (zero)
    4      4     data_len      the data, after the name
    8      8     t_device_ns   device time (ns since the run started) of the first byte
    16     8     t_wall_ns     monotonic ns since the run started when the lab delivered it
    24     -     name, data

A client whose unsent records pass :data:`MAX_BUFFER` bytes (it reads slower than the lab
writes) is dropped: its connection closed with no end record, and the drop counted in the
control status (``tap``: clients, dropped). The lab never waits for a client: sends are
non-blocking, and the socket is served from the runner's own wait, as the control socket
is. With no client connected a chunk costs one check (:attr:`TapServer.clients`).
"""
from __future__ import annotations

import errno
import json
import os
import select
import socket
import struct
import time
from pathlib import Path
from typing import Callable, Iterator, NamedTuple

from .control import close_listener, private_listener

SOCKET = "tap"  # its name in the link directory
FORMAT, VERSION = "navtwin-tap", 1
RECORD = struct.Struct("<BBxxIqq")
TO_HOST, TO_DEVICE, STREAM, DECLARE, END = range(5)
KINDS = {"to_host": TO_HOST, "to_device": TO_DEVICE}
DIRECTIONS = {kind: direction for direction, kind in KINDS.items()}
MAX_BUFFER = 4 << 20  # unsent bytes a client may fall behind by before it is dropped
MAX_CLIENTS = 8
END_WAIT_S = 2.0  # at the end of the run: how long the last records may take to go out
MAX_HELLO = 1 << 20


class TapError(RuntimeError):
    """No tap to read, or a socket that is not a tap; the message is one line with the fix."""


class Record(NamedTuple):
    kind: int
    name: str
    t_device_ns: int
    t_wall_ns: int
    data: bytes

    @property
    def direction(self) -> str | None:
        """``to_host`` / ``to_device`` for a port's chunk, None for a stream's packet."""
        return DIRECTIONS.get(self.kind)


def encode(kind: int, name: str, t_device_ns: int, t_wall_ns: int, data: bytes) -> bytes:
    raw = name.encode()
    return RECORD.pack(kind, len(raw), len(data), t_device_ns, t_wall_ns) + raw + data


class TapServer:
    """The listening socket and its clients. *hello()* gives the hello's fields when a client
    comes (the run's settings and the ports' offsets)."""

    def __init__(self, path: str | os.PathLike, hello: Callable[[], dict],
                 since_start: Callable[[], int], max_buffer: int = MAX_BUFFER) -> None:
        self.path = Path(path)
        self.hello = hello
        self.since_start = since_start  # monotonic ns since the run started: t_wall_ns
        self.max_buffer = max_buffer
        self.streams: dict[str, dict] = {}
        #: connection -> its unsent bytes; empty when no client: the lab's one check
        self.clients: dict[socket.socket, bytearray] = {}
        self.dropped = 0
        self.sock = private_listener(self.path, MAX_CLIENTS)

    def fds(self) -> list:
        return [self.sock, *self.clients]

    def status(self) -> dict:
        return {"path": str(self.path), "clients": len(self.clients), "dropped": self.dropped}

    # -- what the lab delivers -------------------------------------------------------------
    def chunk(self, port: str, direction: str, t_device_ns: int, data: bytes,
              t_wall_ns: int | None = None) -> None:
        """A chunk of *port* going *direction* (``to_host``/``to_device``); *t_wall_ns*
        (None: now) as the recording has it."""
        wall = self.since_start() if t_wall_ns is None else t_wall_ns
        self._send(encode(KINDS[direction], port, t_device_ns, wall, data))

    def declare(self, name: str, linktype: int, doc: str = "") -> None:
        """A stream that is not a port (the air), with its pcapng link type."""
        self.streams[name] = {"linktype": linktype, "doc": doc}
        if self.clients:
            self._send(encode(DECLARE, name, 0, 0, json.dumps(self.streams[name]).encode()))

    def stream(self, name: str, t_device_ns: int, data: bytes) -> None:
        """A packet of declared stream *name* at device time *t_device_ns*."""
        if self.clients:
            self._send(encode(STREAM, name, t_device_ns, self.since_start(), data))

    def _send(self, record: bytes) -> None:
        for conn, pending in list(self.clients.items()):
            pending += record
            self._push(conn, pending)

    def _push(self, conn: socket.socket, pending: bytearray) -> None:
        """Send what *conn* can take now; drop it if it is too far behind or gone."""
        try:
            while pending:
                sent = conn.send(pending)
                del pending[:sent]
        except (BlockingIOError, InterruptedError):
            if len(pending) > self.max_buffer:
                self.dropped += 1  # behind: it goes, the lab does not wait
                self._close(conn)
        except OSError:
            self._close(conn)  # gone

    # -- served from the runner's wait -----------------------------------------------------
    def serve(self, readable) -> None:
        """Accept newcomers, notice clients that left, send what is pending."""
        for s in readable:
            if s is self.sock:
                self._accept()
            elif s in self.clients:
                try:
                    if s.recv(4096):
                        continue  # a client sends nothing; what it does send is ignored
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError:
                    pass
                self._close(s)
        for conn, pending in list(self.clients.items()):
            if pending:
                self._push(conn, pending)

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            if len(self.clients) >= MAX_CLIENTS:
                conn.close()  # it reads an empty stream: no hello
                continue
            conn.setblocking(False)
            hello = {"format": FORMAT, "version": VERSION, **self.hello(),
                     "streams": dict(self.streams)}
            self.clients[conn] = bytearray(json.dumps(hello, separators=(",", ":")).encode()
                                           + b"\n")
            self._push(conn, self.clients[conn])

    def _close(self, conn: socket.socket) -> None:
        self.clients.pop(conn, None)
        conn.close()

    def close(self) -> None:
        """The end of the run: each client gets what is pending and the end record (within
        END_WAIT_S for all of them), then its connection is closed."""
        self._send(encode(END, "", 0, 0, b""))
        deadline = time.monotonic() + END_WAIT_S
        while (late := [c for c, p in self.clients.items() if p]) and \
                (left := deadline - time.monotonic()) > 0:
            for conn in select.select([], late, [], left)[1]:
                self._push(conn, self.clients[conn])
        for conn in list(self.clients):
            self._close(conn)
        close_listener(self.sock, self.path)


class TapClient:
    """A reader of a running lab's tap (in its link directory *link_dir*): :attr:`hello`,
    then :meth:`records` as they come, until the run's end record."""

    def __init__(self, link_dir: str | os.PathLike, timeout: float | None = 10.0) -> None:
        self.path = Path(link_dir) / SOCKET
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        self.sock.settimeout(timeout)
        try:
            self.sock.connect(str(self.path))
        except OSError as e:
            self.sock.close()
            why = "no such socket" if e.errno in (errno.ENOENT, errno.ECONNREFUSED) else e.strerror
            raise TapError(f"link_dir: {self.path}: cannot connect ({why}); is an emulator "
                           "running on this link directory?") from None
        self._buf = bytearray()
        self._hello: dict | None = None
        self.ended = False  # the end record came: the stream is whole

    @property
    def hello(self) -> dict:
        """The run's hello (read when first asked: the lab sends it when its loop serves the
        tap, so a client may connect before the run starts and miss nothing)."""
        if self._hello is None:
            line = self._until_newline()
            try:
                hello = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                hello = None
            if not isinstance(hello, dict) or hello.get("format") != FORMAT:
                raise TapError(f"{self.path}: not a navtwin tap (no hello); is it a navtwin "
                               "emulator's link directory?")
            if hello.get("version") != VERSION:
                raise TapError(f"{self.path}: tap version {hello.get('version')}, this "
                               f"navtwin reads {VERSION}; use the same navtwin as the lab")
            self._hello = hello
        return self._hello

    def _fill(self) -> bool:
        data = self.sock.recv(1 << 16)
        self._buf += data
        return bool(data)

    def _until_newline(self) -> bytes:
        while b"\n" not in self._buf:
            if len(self._buf) > MAX_HELLO or not self._fill():
                raise TapError(f"{self.path}: the lab closed the tap before its hello; it is "
                               "ending, or has as many tap clients as it takes")
        line, _, rest = bytes(self._buf).partition(b"\n")
        self._buf[:] = rest
        return line

    def fileno(self) -> int:
        return self.sock.fileno()

    def records(self) -> Iterator[Record]:
        """The records as they come; stops at the end record (:attr:`ended`) or when the lab
        closes the tap without one (it dropped this client, or died)."""
        streams = self.hello["streams"]
        buf = self._buf
        while not self.ended:
            while len(buf) < RECORD.size or len(buf) < RECORD.size + sum(
                    RECORD.unpack_from(buf)[1:3]):
                if not self._fill():
                    return
            kind, name_len, data_len, t_dev, t_wall = RECORD.unpack_from(buf)
            start = RECORD.size + name_len
            record = Record(kind, bytes(buf[RECORD.size:start]).decode(), t_dev, t_wall,
                            bytes(buf[start:start + data_len]))
            del buf[:start + data_len]
            if kind == END:
                self.ended = True
                return
            if kind == DECLARE:
                streams[record.name] = json.loads(record.data)
            yield record

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> "TapClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
