"""Recordings: the bytes of each port with their times, in a directory.

Layout (``docs/recording.md``)::

    DIR/recording.json     {"format": "navtwin-recording", "version": 1, "ports": {...}, ...}
    DIR/<port>.bin         every byte of the port, in order
    DIR/<port>.csv         one line per chunk: offset,size,t_device_ns,t_wall_ns

A chunk is one write by a device (emulator) or one read by the host. ``t_device_ns`` is the
device clock at the chunk's first byte (emulator recordings; empty in host recordings);
``t_wall_ns`` is the wall time of the write (emulator, real time only) or the arrival time
of the read (host, monotonic ns since the run started). Both are integers, so a replay
feeds exactly the recorded chunks at exactly the recorded times.
"""
from __future__ import annotations

import heapq
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

FORMAT = "navtwin-recording"
VERSION = 1
META = "recording.json"
INDEX_HEADER = "offset,size,t_device_ns,t_wall_ns"


@dataclass(frozen=True, slots=True)
class Chunk:
    port: str
    offset: int
    data: bytes
    t_device_ns: int | None
    t_wall_ns: int | None


class PortWriter:
    def __init__(self, directory: Path, name: str) -> None:
        self.name = name
        self._bin = open(directory / f"{name}.bin", "wb")
        self._idx = open(directory / f"{name}.csv", "w", newline="")
        self._idx.write(INDEX_HEADER + "\n")
        self.offset = 0

    def write(self, data: bytes, t_device_ns: int | None = None, t_wall_ns: int | None = None) -> None:
        if not data:
            return
        self._bin.write(data)
        self._idx.write(f"{self.offset},{len(data)},"
                        f"{'' if t_device_ns is None else t_device_ns},"
                        f"{'' if t_wall_ns is None else t_wall_ns}\n")
        self.offset += len(data)

    def flush(self) -> None:
        self._bin.flush()
        self._idx.flush()

    def close(self) -> None:
        self._bin.close()
        self._idx.close()


class RecordingWriter:
    """Write a recording; ``meta`` is free JSON (scenario, seed, port settings, source)."""

    def __init__(self, directory: str | os.PathLike, meta: dict | None = None) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.meta = dict(meta or {})
        self.ports: dict[str, PortWriter] = {}

    def port(self, name: str) -> PortWriter:
        if name not in self.ports:
            self.ports[name] = PortWriter(self.directory, name)
        return self.ports[name]

    def write_meta(self) -> None:
        meta = {"format": FORMAT, "version": VERSION, **self.meta,
                "ports": {**self.meta.get("ports", {}),
                          **{n: self.meta.get("ports", {}).get(n, {}) for n in self.ports}}}
        tmp = self.directory / (META + ".tmp")
        tmp.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
        os.replace(tmp, self.directory / META)

    def flush(self) -> None:
        for p in self.ports.values():
            p.flush()

    def close(self) -> None:
        for p in self.ports.values():
            p.close()
        self.write_meta()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class RecordingError(ValueError):
    pass


class Recording:
    """Read a recording directory."""

    def __init__(self, directory: str | os.PathLike) -> None:
        self.directory = Path(directory)
        meta_path = self.directory / META
        if not meta_path.is_file():
            raise RecordingError(f"{self.directory}: no {META}; is this a navtwin recording directory?")
        try:
            self.meta = json.loads(meta_path.read_text())
        except json.JSONDecodeError as e:
            raise RecordingError(f"{meta_path}: not valid JSON ({e})") from None
        if self.meta.get("format") != FORMAT:
            raise RecordingError(f"{meta_path}: format is not {FORMAT!r}")
        if self.meta.get("version", 0) > VERSION:
            raise RecordingError(f"{meta_path}: version {self.meta['version']} is newer than this "
                                 f"navtwin reads ({VERSION}); upgrade navtwin")
        self.ports = sorted(self.meta.get("ports", {}))

    def path(self, port: str) -> Path:
        if port not in self.ports:
            raise RecordingError(f"{self.directory}: no port {port!r} (it has {', '.join(self.ports)})")
        return self.directory / f"{port}.bin"

    def read_bytes(self, port: str) -> bytes:
        return self.path(port).read_bytes()

    def chunks(self, port: str) -> Iterator[Chunk]:
        data = self.read_bytes(port)
        index = self.directory / f"{port}.csv"
        lines = index.read_text().splitlines()
        if not lines or lines[0] != INDEX_HEADER:
            raise RecordingError(f"{index}: the first line must be {INDEX_HEADER!r}")
        for n, line in enumerate(lines[1:], 2):  # plain integers: split, no csv dialect
            try:
                off, size, dev, wall = line.split(",")
                off, size = int(off), int(size)
                yield Chunk(port, off, data[off:off + size], int(dev) if dev else None,
                            int(wall) if wall else None)
            except ValueError:
                raise RecordingError(f"{index}:{n}: expected offset,size,t_device_ns,t_wall_ns "
                                     f"as integers, got {line!r}") from None

    def merged(self, ports: list[str] | None = None, clock: str = "t_wall_ns") -> Iterator[Chunk]:
        """Chunks of several ports in time order (ties: port name order) by *clock*."""
        def keyed(i: int, port: str):
            for c in self.chunks(port):
                yield getattr(c, clock) or 0, i, c.offset, c

        streams = [keyed(i, p) for i, p in enumerate(sorted(ports or self.ports))]
        for *_, chunk in heapq.merge(*streams):
            yield chunk
