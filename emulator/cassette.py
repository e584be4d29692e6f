"""Cassettes: what a user's host code exchanged with the lab, recorded once and replayed
with no emulator process (the ``navtwin_cassette`` fixture of the pytest plugin).

Recording (:class:`Recorder`): the host code gets, per port, the slave of a PTY pair the
cassette owns; one relay thread copies the lab's bytes to it and the host's writes to the
lab's port, and logs every chunk it relays with its direction, port and time. Replay
(:class:`Player`): the same PTYs, served from the cassette: the recorded device chunks in
their recorded order, each released once the host's writes that came before it in the
recording have come (so an answer never precedes its question), and the host's writes
compared with the recorded ones as they come; a differing write stops the serving and
:meth:`Player.check` fails with the frame-level diff (protocols.diff) in the port's format.

Format (a directory per test, docs/testing.md "A cassette test"):

``cassette.json``
    ``{"version": 1, "scenario", "seed", "ports": {port: {"format", "escaped"}},
    "chunks": [{"port", "dir", "offset", "size", "t"}, ...]}``; ``dir`` is ``"read"``
    (device -> host code) or ``"write"`` (host code -> device), ``offset``/``size`` locate
    the chunk in that port's file of that direction, ``t`` is seconds since the start;
    the list is in relay order.
``<port>.read.bin``, ``<port>.write.bin``
    the bytes of each direction, the chunks back to back.
"""
from __future__ import annotations

import errno
import json
import os
import select
import threading
import time
import tty
from pathlib import Path

from ..protocols import ports as lab_ports
from ..protocols.diff import diff_bytes

VERSION = 1
INDEX = "cassette.json"
POLL_S = 0.05  # how often the relay thread looks at its stop flag


class CassetteError(AssertionError):
    """A cassette that cannot be replayed, or a replay the host code did not match."""


def _pty() -> tuple[int, int, str]:
    """A raw PTY pair: (master, slave, slave path); the slave stays open here so the master
    never sees a hang-up while the host code opens and closes its end."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


class _Relay:
    """One select loop over the PTY masters (and, recording, the lab's ports)."""

    def __init__(self, names) -> None:
        self.t0 = time.monotonic()
        self.masters: dict[str, int] = {}
        self._slaves: list[int] = []
        self.ports: dict[str, str] = {}
        for name in names:
            master, slave, path = _pty()
            self.masters[name], self.ports[name] = master, path
            self._slaves.append(slave)
        self.out: dict[int, bytearray] = {}  # fd -> bytes waiting for the fd to take them
        self.gone: set[int] = set()  # lab ports that hung up (the lab ended): not read again
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="navtwin-cassette", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def send(self, fd: int, data: bytes) -> None:
        self.out.setdefault(fd, bytearray()).extend(data)

    def _flush(self, fd: int) -> None:
        buf = self.out[fd]
        try:
            del buf[:os.write(fd, buf)]
        except BlockingIOError:
            pass
        except OSError as e:  # a lab port gone takes no more writes
            if e.errno != errno.EIO:
                raise
            buf.clear()

    def _run(self) -> None:
        while not self._stop.is_set():
            if self.hang_up():
                self._close_masters()
                return
            self.step()
            readers = [fd for fd in self.readers() if fd not in self.gone]
            writers = [fd for fd, buf in self.out.items() if buf]
            ready_r, ready_w, _ = select.select(readers, writers, [], POLL_S)
            for fd in ready_w:
                self._flush(fd)
            for fd in ready_r:
                try:
                    data = os.read(fd, 4096)
                except OSError as e:  # a lab port gone (the lab ended) reads EIO
                    if e.errno != errno.EIO:
                        raise
                    self.gone.add(fd)
                    continue
                if data:
                    self.got(fd, data)

    def step(self) -> None:
        """Between selects: what the loop has to do next (replay: release chunks)."""

    def hang_up(self) -> bool:
        """Whether to hang up the host code's PTYs now (replay: a write differed)."""
        return False

    def _close_masters(self) -> None:
        for fd in self.masters.values():
            os.close(fd)
        self.masters = {}

    def readers(self) -> list[int]:
        return list(self.masters.values())

    def got(self, fd: int, data: bytes) -> None:
        raise NotImplementedError

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        self._close_masters()
        for fd in self._slaves:
            os.close(fd)


class Recorder(_Relay):
    """Sits between the host code and a running lab (emulator.api.Lab), logging the exchange."""

    def __init__(self, lab, scenario) -> None:
        super().__init__(lab.ports)
        self.lab = lab
        self.scenario = scenario
        self.lab_fds: dict[str, int] = {}
        for name, path in lab.ports.items():
            fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            tty.setraw(fd)
            self.lab_fds[name] = fd
        self._port_of = {fd: n for n, fd in (*self.masters.items(), *self.lab_fds.items())}
        self.chunks: list[dict] = []
        self.data: dict[tuple[str, str], bytearray] = {}

    def readers(self) -> list[int]:
        return [*self.masters.values(), *self.lab_fds.values()]

    def _log(self, port: str, direction: str, data: bytes) -> None:
        buf = self.data.setdefault((port, direction), bytearray())
        self.chunks.append({"port": port, "dir": direction, "offset": len(buf), "size": len(data),
                            "t": round(time.monotonic() - self.t0, 6)})
        buf.extend(data)

    def got(self, fd: int, data: bytes) -> None:
        port = self._port_of[fd]
        if fd == self.masters[port]:  # the host code wrote
            self._log(port, "write", data)
            self.send(self.lab_fds[port], data)
        else:  # the device sent: logged as it came, in order with the host's writes
            self._log(port, "read", data)
            self.send(self.masters[port], data)

    def save(self, directory: Path) -> None:
        """Write the cassette (replacing one there)."""
        directory.mkdir(parents=True, exist_ok=True)
        for old in directory.glob("*.bin"):
            old.unlink()
        for (port, direction), buf in self.data.items():
            (directory / f"{port}.{direction}.bin").write_bytes(bytes(buf))
        ports = {}
        for name in self.ports:
            settings = self.scenario.ports.get(name, {})
            ports[name] = {"format": lab_ports.get(name).frame_format,
                           "escaped": lab_ports.escaped(settings)}
        index = {"version": VERSION, "scenario": self.lab.info.get("scenario"),
                 "seed": self.lab.info.get("seed"), "ports": ports, "chunks": self.chunks}
        (directory / INDEX).write_text(json.dumps(index, indent=1) + "\n")

    def close(self) -> None:
        super().close()
        for fd in self.lab_fds.values():
            os.close(fd)


class Player(_Relay):
    """Serves a cassette's device bytes and checks the host code's writes against it."""

    def __init__(self, directory: Path) -> None:
        index_path = directory / INDEX
        if not index_path.exists():
            raise CassetteError(f"no cassette at {directory}: record it once with "
                                f"'pytest --navtwin-record' (the lab runs for that run only)")
        index = json.loads(index_path.read_text())
        if index.get("version") != VERSION:
            raise CassetteError(f"{index_path}: cassette version {index.get('version')!r}, "
                                f"this navtwin replays {VERSION}; record it again with "
                                f"'pytest --navtwin-record'")
        self.index = index
        super().__init__(index["ports"])
        self.data = {(c["port"], c["dir"]): (directory / f"{c['port']}.{c['dir']}.bin").read_bytes()
                     for c in index["chunks"]}
        self.received = {name: bytearray() for name in self.ports}
        self._port_of = {fd: n for n, fd in self.masters.items()}
        self._next = 0  # the first chunk not yet served or awaited
        self.mismatch: str | None = None  # the port whose write differed

    def _written(self, port: str) -> bytes:
        return self.data.get((port, "write"), b"")

    def step(self) -> None:
        chunks = self.index["chunks"]
        while self._next < len(chunks):
            c = chunks[self._next]
            end = c["offset"] + c["size"]
            if c["dir"] == "read":
                self.send(self.masters[c["port"]], self.data[(c["port"], "read")][c["offset"]:end])
            elif len(self.received[c["port"]]) < end:
                return  # the host code has not written this yet: the device waits for it
            self._next += 1

    def got(self, fd: int, data: bytes) -> None:
        port = self._port_of[fd]
        got = self.received[port]
        got.extend(data)
        recorded = self._written(port)
        if got != recorded[:len(got)]:
            self.mismatch = port

    def hang_up(self) -> bool:
        # the device would not have answered a write it never saw: the host code's reads
        # end at once (its port hangs up) rather than waiting out its own timeouts
        return self.mismatch is not None

    def check(self) -> None:
        """Raise :class:`CassetteError` with the frame-level diff of every port whose
        writes differ from the recorded ones (a write changed, missing or extra)."""
        problems = []
        for port, got in self.received.items():
            recorded = self._written(port)
            if bytes(got) == recorded:
                continue
            settings = self.index["ports"][port]
            diff = diff_bytes(recorded, bytes(got), settings["format"],
                              escaped=settings["escaped"], names=("recorded", "written"))
            problems.append(f"port {port}: the host code's writes differ from the cassette's "
                            f"({len(recorded)} bytes recorded, {len(got)} written):\n{diff.text()}")
        if problems:
            raise CassetteError("\n".join(problems) + "\nif the change is meant, record the "
                                "cassette again with 'pytest --navtwin-record'")
