"""Recordings: the bytes of each port with their times, in a directory.

Layout (``docs/emulator.md``, "Recordings")::

    DIR/recording.json     {"format": "navtwin-recording", "version": 1, "complete": true,
                            "ports": {...}, ...}
    DIR/<port>.bin         every byte of the port, in order
    DIR/<port>.csv         one line per chunk: offset,size,t_device_ns,t_wall_ns
                           (a host's, version 2: ...,read_offset,reconnects,contended)
    DIR/faults.jsonl       the fault ledger (emulator recordings): one JSON object a line
    DIR/<stream>.bin/.csv  a stream that is not a port (the emulator's ``air``), as a port's

A chunk is one write by a device (emulator) or one read by the host. ``t_device_ns`` is the
device clock at the chunk's first byte (emulator recordings; empty in host recordings);
``t_wall_ns`` is the wall time of the write (emulator, real time only) or the arrival time
of the read (host, monotonic ns since the run started). Both are integers, so a replay
feeds exactly the recorded chunks at exactly the recorded times.

Streams. Besides its ports a recording may hold streams that no port carries, listed under
``"streams"`` in recording.json, never under ``"ports"`` (so every tool that walks the ports
is unchanged): ``{"air": {"linktype": 195, "doc": "..."}}``. A stream's files are a port's
(one chunk = one packet of the stream, ``t_device_ns`` = when it happened in device time);
``linktype`` is its packets' pcap link type (tcpdump.org/linktypes.html), so a capture
(protocols.capture) can give the stream an interface without knowing what it is. The
emulator records ``air``: each chunk one IEEE 802.15.4 PSDU with its FCS (link type 195),
``t_device_ns`` its first bit on the air (emulator.radio). :attr:`Recording.streams` lists
them; :meth:`Recording.chunks` reads a stream's chunks as a port's.

Read columns (version 2, host recordings). Each read also says where it was in what the host
read from the port, counted by the port's reader as it read (:class:`Read`): ``read_offset``,
the bytes it had read from the port before this read (since the host started, over every
reopen), ``reconnects`` and ``contended``, how often it had reopened the port and found its
bytes taken by another reader. A read missing from the recording leaves a gap in
``read_offset``, and reordered reads put it out of order: the audit (lab.audit) proves the
recording whole with them. The columns may be empty (what the host sent, ``xbee.tx``). A
recording's ``version`` is the oldest that reads it: 2 with the read columns, else 1 (the
emulator's, byte for byte as before).

Crash safety. ``recording.json`` is written when the recording starts, with
``"complete": false``, and replaced atomically at close with ``"complete": true`` (false if
a write failed). The writer buffers data and index in memory and writes them on
:meth:`RecordingWriter.flush`, each port's data before its index, so the index on disk never
names bytes that are not on disk: a killed process leaves a replayable prefix up to its
last flush. Callers flush at least every ``FLUSH_S``; the writer flushes itself when
``FLUSH_BYTES`` are buffered.

Fault ledger. Every injection of a fault, one JSON object per line, in the order they
happened (emulator.ledger describes an entry): ``kind`` (a string), ``fault`` (an integer
>= 0 or null), ``port`` (a port of the recording or null), ``direction`` ("to_host",
"to_device" or null), ``t_ns`` (an integer), ``start`` and ``end`` (integers, 0 <= start <=
end, or both null), any other keys the kind's details. An emulator recording always has the
file, empty when no fault acted; a recording without it (older ones, the host's) has an
empty ledger. It is flushed with the other files, after the ports' data; the emulator adds
an entry as its bytes are delivered, just before it buffers them, so in a killed run's
recording the last entries may name bytes past a port's recorded end; they are skipped, as
is a partial last line.

Reading validates: the meta's shape, and each index against its data file (contiguous
offsets from 0, sizes in (0, MAX_CHUNK], integer non-decreasing times). Data files are
streamed, never read whole. A truncated tail (chunks past the end of the data, a partial
last index line) is what a crash leaves: in a recording that is not complete it is skipped
and reported in :attr:`Recording.skipped`; in a complete one it is damage, an error unless
``salvage`` asks for the intact prefix.
"""
from __future__ import annotations

import bisect
import errno
import heapq
import json
import os
import re
import stat
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, NamedTuple

from .serial import BAUDS

FORMAT = "navtwin-recording"
READS_VERSION = 2  # the first with the read columns
VERSION = READS_VERSION  # the newest this navtwin reads
META = "recording.json"
FAULTS = "faults.jsonl"
DIRECTIONS = ("to_host", "to_device")
_MAX_FAULT_LINE = 1 << 16
INDEX_HEADER = "offset,size,t_device_ns,t_wall_ns"
READS_HEADER = INDEX_HEADER + ",read_offset,reconnects,contended"
FLUSH_S = 0.5  # callers flush at least this often: a kill loses at most ~1 s of wall time
FLUSH_BYTES = 1 << 20  # buffered bytes (all files) that make the writer flush by itself
MAX_CHUNK = 1 << 24  # no writer makes a chunk this big: a larger size is not a chunk
PORT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")  # a file stem in DIR, no path
_MAX_INDEX_LINE = 160  # seven integers and six commas
# an index line: offset,size,t_device_ns,t_wall_ns (the times may be empty), then in a host's
# index read_offset,reconnects,contended (all three, or all empty), CR LF or LF
_ENTRY = re.compile(rb"([0-9]{1,19}),([0-9]{1,19}),([0-9]{0,19}),([0-9]{0,19})"
                    rb"(?:,([0-9]{1,19}),([0-9]{1,19}),([0-9]{1,19})|(,,,))?\r*\n")


def _entry_problem(line: bytes, header: str) -> str:
    """Why an index line that is not an entry of an index with *header* is not one."""
    fields = line.rstrip(b"\r\n").split(b",")
    if len(fields) != header.count(",") + 1:
        return f"expected {header}, got {_text(line)!r}"
    return f"expected non-negative integers {header}, got {_text(line)!r}"


_FIX = {errno.ENOSPC: "the filesystem is full; free space or write to another filesystem",
        errno.EDQUOT: "the disk quota is used up; free space or write elsewhere",
        errno.EFBIG: "the file is larger than allowed (ulimit -f or the filesystem's limit); "
                     "raise the limit or write elsewhere",
        errno.EIO: "the device reported an I/O error; check the disk (dmesg) or write elsewhere"}


def write_failure(path, err: OSError) -> str:
    """One line for a write to *path* that failed with *err*: the problem and the fix."""
    return (f"{path}: {err.strerror or err}; "
            f"{_FIX.get(err.errno, 'check the path and its permissions, or write elsewhere')}")



def _numbered_lines(fh, limit: int, damaged, first: int = 1) -> Iterator[tuple[int, bytes | None]]:
    """``(number, line)`` of each whole line of *fh*, read at most *limit* bytes at a time
    (bounded memory on a damaged file), then ``(number, None)`` for a partial last line; a
    line longer than *limit* is ``damaged(number, problem)``, which raises."""
    n = first - 1
    while line := fh.readline(limit + 1):
        n += 1
        if not line.endswith(b"\n"):
            if len(line) > limit:
                damaged(n, f"a line longer than {limit} bytes")
            yield n, None
            return
        yield n, line

class RecordingWriteError(Exception):
    """A recording that cannot be created or written: one line naming the file and the fix.
    ``written``: bytes of the failed flush that did reach the file."""

    def __init__(self, message: str, written: int = 0) -> None:
        super().__init__(message)
        self.written = written


class Read(NamedTuple):
    """Where a host's read was in what it read from its port (the module docstring)."""
    offset: int  # bytes read from the port before it
    reconnects: int  # reopens of the port before it
    contended: int  # reads before it that found the bytes taken by another reader


class Stream(NamedTuple):
    """A recorded stream that is not a port: its name, its packets' pcap link type, what it
    is."""
    name: str
    linktype: int
    doc: str


@dataclass(frozen=True, slots=True)
class Chunk:
    port: str
    offset: int
    data: bytes
    t_device_ns: int | None
    t_wall_ns: int | None
    read: Read | None = None  # a host's read columns


class _File:
    """An append-only file of the recording: bytes are buffered until :meth:`flush`."""

    def __init__(self, writer: "RecordingWriter", name: str, replace: bool) -> None:
        self.path = writer.directory / name
        flags = (os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
                 | (os.O_TRUNC if replace else os.O_EXCL))
        try:
            self.fd = os.open(name, flags, 0o644, dir_fd=writer.dirfd)
        except OSError as e:
            raise RecordingWriteError(_refusal(self.path, e)) from None
        if not stat.S_ISREG(os.fstat(self.fd).st_mode):
            os.close(self.fd)
            raise RecordingWriteError(f"{self.path}: not a regular file; remove it or record "
                                      f"into a new directory")
        self._writer = writer
        self._buf = bytearray()

    def append(self, data: bytes) -> None:
        self._buf += data
        self._writer.buffered += len(data)

    def flush(self) -> None:
        buf, done = self._buf, 0
        try:
            with memoryview(buf) as view:
                while done < len(buf):
                    done += os.write(self.fd, view[done:])
        except OSError as e:
            raise RecordingWriteError(write_failure(self.path, e), done) from None
        finally:
            self._writer.buffered -= len(buf)
            buf.clear()  # after a failure nothing more is written: see RecordingWriter

    def keep(self, nbytes: int) -> None:
        """Drop what is buffered after the first *nbytes*."""
        self._writer.buffered -= len(self._buf) - nbytes
        del self._buf[nbytes:]

    def close(self) -> None:
        os.close(self.fd)


def _refusal(path: Path, e: OSError) -> str:
    if e.errno == errno.ELOOP:
        return f"{path}: is a symbolic link; navtwin does not record through links: remove it"
    if e.errno == errno.EEXIST:
        return f"{path}: exists; record into a new directory"
    return write_failure(path, e)


class PortWriter:
    def __init__(self, writer: "RecordingWriter", name: str) -> None:
        if not PORT_NAME.fullmatch(name):
            raise ValueError(f"port name {name!r} is not a plain file name")
        self.name = name
        self._writer = writer
        self._bin = _File(writer, f"{name}.bin", writer.replace)
        self._idx = _File(writer, f"{name}.csv", writer.replace)
        self._idx.append((READS_HEADER if writer.reads else INDEX_HEADER).encode() + b"\n")
        self._idx.flush()  # now: an index on disk always has its header
        self.offset = 0  # bytes written to this port so far (flushed or not)
        self._ends: list[tuple[int, int]] = []  # buffered chunks: (data end, index end)
        self._data_end = self._index_end = 0  # ... the last one's

    def write(self, data: bytes, t_device_ns: int | None = None,
              t_wall_ns: int | None = None, read: Read | None = None) -> None:
        """Buffer one chunk (*read*: its read columns, in a writer with ``reads``); may flush
        (and so raise :class:`RecordingWriteError`)."""
        writer = self._writer
        if not data or writer.error is not None:
            return
        size = len(data)
        if size > MAX_CHUNK:
            raise ValueError(f"a chunk of {size} bytes is over MAX_CHUNK; write it in parts")
        if read is not None and not writer.reads:
            raise ValueError("read columns need a RecordingWriter made with reads=True")
        # an index line per chunk: f-strings, the cheapest text of a few integers (None: empty)
        line = (f"{self.offset},{size},{'' if t_device_ns is None else t_device_ns},"
                f"{'' if t_wall_ns is None else t_wall_ns}")
        if writer.reads:
            line += "".join("," if f is None else f",{f}" for f in read or (None,) * len(Read._fields))
        line = (line + "\n").encode()
        self._data_end += size
        self._index_end += len(line)
        self._ends.append((self._data_end, self._index_end))
        self._bin.append(data)
        self._idx.append(line)
        self.offset += size
        if writer.buffered >= FLUSH_BYTES:
            writer.flush()

    def flush(self) -> None:
        ends, self._ends = self._ends, []
        self._data_end = self._index_end = 0
        try:
            self._bin.flush()  # the data first: the index never names bytes not on disk
        except RecordingWriteError as e:
            # index the chunks that did reach the disk whole, so that they replay
            whole = bisect.bisect_right(ends, (e.written, 1 << 62))
            self._idx.keep(ends[whole - 1][1] if whole else 0)
            try:
                self._idx.flush()
            except RecordingWriteError:
                pass  # the first failure is the one reported
            raise
        self._idx.flush()

    def close(self) -> None:
        self._bin.close()
        self._idx.close()


def _open_dir(directory: Path) -> int:
    """The recording directory, created if missing, never through a symbolic link."""
    try:
        directory.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.mkdir(directory, 0o755)
        except FileExistsError:
            pass
        if directory.is_symlink():
            raise RecordingWriteError(f"{directory}: is a symbolic link; navtwin does not record "
                                      f"through links: pass the directory itself")
        return os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as e:
        if e.errno == errno.ENOTDIR:
            raise RecordingWriteError(f"{directory}: not a directory; pass a directory path") \
                from None
        raise RecordingWriteError(write_failure(directory, e)) from None


class RecordingWriter:
    """Write a recording; ``meta`` is free JSON (scenario, seed, port settings, source);
    *reads*: a host's, each chunk one read with its read columns (the module docstring).

    Every port of ``meta["ports"]`` gets its files at once, so a silent port is recorded as
    such. The directory must be new or empty unless *replace* (then files of the same names
    are truncated). The meta is on disk from the start (``"complete": false``). After a write
    fails, :attr:`error` holds it, nothing more is written, and :meth:`close` leaves the meta
    saying ``"complete": false``; the error is raised once, where it happened.
    """

    def __init__(self, directory: str | os.PathLike, meta: dict | None = None, *,
                 replace: bool = False, reads: bool = False) -> None:
        self.directory = Path(directory)
        self.meta = dict(meta or {})
        self.replace = replace
        self.reads = reads
        self.ports: dict[str, PortWriter] = {}
        self.streams: dict[str, PortWriter] = {}  # streams that are not ports (their meta:
        # meta["streams"])
        self.files: dict[str, _File] = {}  # other append-only files (truth.csv)
        self.buffered = 0
        self.error: RecordingWriteError | None = None
        self.dirfd = _open_dir(self.directory)
        try:
            if not replace and os.listdir(self.dirfd):
                raise RecordingWriteError(f"{self.directory}: exists and is not an empty "
                                          f"directory; choose a new directory")
            for name in self.meta.get("ports", {}):
                self.ports[name] = PortWriter(self, name)
            self.write_meta(complete=False)
        except BaseException:
            self._close_files()
            os.close(self.dirfd)
            raise

    def port(self, name: str) -> PortWriter:
        if name not in self.ports:
            self.ports[name] = PortWriter(self, name)
            self.write_meta(complete=False)  # a crash leaves a meta that lists the port
        return self.ports[name]

    def stream(self, name: str, linktype: int, doc: str) -> PortWriter:
        """Stream *name* (not a port; the module docstring), its packets of pcap link type
        *linktype*, described by *doc*: its writer, made on first use."""
        if name not in self.streams:
            if name in self.meta.get("ports", {}) or name in self.ports:
                raise ValueError(f"stream {name!r} is also a port; give the stream another name")
            if not 0 <= linktype <= 0xFFFF:
                raise ValueError(f"stream {name!r}: link type {linktype} is not 0..65535")
            self.streams[name] = PortWriter(self, name)
            self.meta.setdefault("streams", {})[name] = {"linktype": linktype, "doc": doc}
            self.write_meta(complete=False)  # a crash leaves a meta that lists the stream
        return self.streams[name]

    def file(self, name: str) -> _File:
        """An append-only file beside the ports (flushed after them)."""
        if name not in self.files:
            self.files[name] = _File(self, name, self.replace)
        return self.files[name]

    def fault(self, entry: dict) -> None:
        """Buffer one fault-ledger entry (a JSON object) as a line of faults.jsonl."""
        self.file(FAULTS).append(json.dumps(entry, sort_keys=True, separators=(",", ":"))
                                 .encode() + b"\n")

    def write_file(self, name: str, data: bytes) -> None:
        """A whole small file, written now."""
        f = _File(self, name, self.replace)
        try:
            f.append(data)
            self._guard(f.flush)
        finally:
            f.close()

    def write_meta(self, complete: bool) -> None:
        ports = self.meta.get("ports", {})
        # the oldest version that reads it: an emulator recording is what it always was
        version = READS_VERSION if self.reads else 1
        meta = {"format": FORMAT, "version": version, **self.meta, "complete": complete,
                "ports": {**ports, **{n: ports.get(n, {}) for n in self.ports}},
                **({"write_error": str(self.error)} if self.error else {})}
        tmp = META + ".tmp"
        t = _File(self, tmp, replace=True)  # a tmp left by a killed run is ours to replace
        try:
            t.append(json.dumps(meta, indent=2, sort_keys=True).encode() + b"\n")
            t.flush()
            os.replace(tmp, META, src_dir_fd=self.dirfd, dst_dir_fd=self.dirfd)
        except OSError as e:
            raise RecordingWriteError(write_failure(self.directory / META, e)) from None
        finally:
            t.close()

    def _guard(self, action) -> None:
        if self.error is not None:
            return
        try:
            action()
        except RecordingWriteError as e:
            self.error = e
            raise

    def flush(self) -> None:
        """Write what is buffered: each port's and stream's data, then its index, then the
        other files."""
        def everything():
            for p in (*self.ports.values(), *self.streams.values()):
                p.flush()
            for f in self.files.values():
                f.flush()
        self._guard(everything)

    def close(self) -> None:
        """Flush and write the final meta; raises only a failure not raised before."""
        if self.dirfd < 0:
            return
        failed_before = self.error is not None
        try:
            try:
                self.flush()
            except RecordingWriteError:
                pass
            self._close_files()
            try:
                self.write_meta(complete=self.error is None)
            except RecordingWriteError as e:
                # the meta on disk still says "complete": false, which is true
                self.error = self.error or e
        finally:
            os.close(self.dirfd)
            self.dirfd = -1
        if self.error is not None and not failed_before:
            raise self.error

    def _close_files(self) -> None:
        for p in (*self.ports.values(), *self.streams.values()):
            p.close()
        for f in self.files.values():
            f.close()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class RecordingError(ValueError):
    """A recording that cannot be read: one line naming the file and the fix (a newline in a
    path or value it quotes is shown as ``\\n``)."""

    def __init__(self, message: str) -> None:
        super().__init__(message.replace("\n", "\\n"))


def _limit(e: Exception) -> str:
    """The limit json hit beyond its syntax (the nesting depth, an integer's digits)."""
    if isinstance(e, RecursionError):
        return "arrays or objects nested too deeply"
    return f"an integer of more than {sys.get_int_max_str_digits()} digits"


def _check_meta(meta, where: Path) -> None:
    """One-line errors for a recording.json whose shape is not a recording's."""
    def fail(problem: str) -> None:
        raise RecordingError(f"{where}: {problem}; this is not a usable navtwin recording "
                             f"(re-record it, or restore recording.json)")

    if not isinstance(meta, dict):
        fail(f"the top level is {type(meta).__name__}, not an object")
    if meta.get("format") != FORMAT:
        fail(f"format is {meta.get('format')!r}, not {FORMAT!r}")
    version = meta.get("version")
    if type(version) is not int or version < 1:
        fail(f"version {version!r} is not a positive integer")
    if version > VERSION:
        raise RecordingError(f"{where}: version {version} is newer than this navtwin reads "
                             f"({VERSION}); upgrade navtwin")
    if "complete" in meta and type(meta["complete"]) is not bool:
        fail(f"complete {meta['complete']!r} is not true or false")
    ports = meta.get("ports")
    if not isinstance(ports, dict) or not ports:
        fail(f"ports {ports!r} is not a non-empty object of port objects")
    for name, port in ports.items():
        if not PORT_NAME.fullmatch(name):
            fail(f"port name {name!r} is not a plain file name")
        if not isinstance(port, dict):
            fail(f"port {name!r} is {type(port).__name__}, not an object")
        baud = port.get("baud", BAUDS[0])
        if type(baud) is not int or not BAUDS[0] <= baud <= BAUDS[1]:
            fail(f"port {name!r} baud {baud!r} is not an integer from {BAUDS[0]} to {BAUDS[1]}")
        api = port.get("api_mode", 1)
        if type(api) is not int or api not in (1, 2):
            fail(f"port {name!r} api_mode {api!r} is not 1 or 2")
    streams = meta.get("streams", {})
    if not isinstance(streams, dict):
        fail(f"streams {streams!r} is not an object of stream objects")
    for name, stream in streams.items():
        if not PORT_NAME.fullmatch(name) or name in ports:
            fail(f"stream name {name!r} is not a plain file name apart from the ports'")
        if not isinstance(stream, dict):
            fail(f"stream {name!r} is {type(stream).__name__}, not an object")
        linktype = stream.get("linktype")
        if type(linktype) is not int or not 0 <= linktype <= 0xFFFF:
            fail(f"stream {name!r} linktype {linktype!r} is not an integer from 0 to 65535")
        if not isinstance(stream.get("doc", ""), str):
            fail(f"stream {name!r} doc {stream['doc']!r} is not a string")


def _lines(path: Path) -> int:
    with open(path, "rb") as fh:
        return sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 16), b""))


def _text(line: bytes) -> str:
    return line.strip().decode("ascii", "backslashreplace")


class Recording:
    """Read a recording directory, validating it (see the module docstring)."""

    def __init__(self, directory: str | os.PathLike, *, salvage: bool = False) -> None:
        self.directory = Path(directory)
        meta_path = self.directory / META
        if not meta_path.is_file():
            raise RecordingError(f"{self.directory}: no {META}; is this a navtwin recording directory?")
        try:
            self.meta = json.loads(meta_path.read_bytes().decode("utf-8"))
        except UnicodeDecodeError as e:
            raise RecordingError(f"{meta_path}: not UTF-8 text ({e.reason} at byte {e.start}); "
                                 f"restore recording.json or re-record") from None
        except json.JSONDecodeError as e:
            raise RecordingError(f"{meta_path}: not valid JSON ({e}); restore recording.json "
                                 f"or re-record") from None
        except (ValueError, RecursionError) as e:  # json's own limits: digits, nesting
            raise RecordingError(f"{meta_path}: not a recording's JSON ({_limit(e)}); restore "
                                 f"recording.json or re-record") from None
        except OSError as e:
            raise RecordingError(f"{meta_path}: {e.strerror}; check the directory") from None
        _check_meta(self.meta, meta_path)
        self.ports = sorted(self.meta["ports"])
        #: streams that are not ports (the module docstring): name -> Stream
        self.streams = {name: Stream(name, s["linktype"], s.get("doc", ""))
                        for name, s in sorted(self.meta.get("streams", {}).items())}
        # a recording from before the "complete" field was closed normally or not at all: the
        # old writer gave no way to tell, and a normal close is the usual case
        self.complete = self.meta.get("complete", True)
        self.salvage = salvage
        self.reads: dict[str, bool] = {}  # port -> whether its index has the read columns
        self._intact: dict[str, int] = {}  # port -> chunks to replay
        self.sizes: dict[str, int] = {}  # port -> bytes those chunks hold
        self.skipped: dict[str, dict] = {}  # port -> {"chunks", "bytes", "why"}
        for port in (*self.ports, *self.streams):
            self._scan(port)

    def path(self, port: str) -> Path:
        """The data file of port (or stream) *port*."""
        if port not in self.ports and port not in self.streams:
            raise RecordingError(f"{self.directory}: no port or stream {port!r} (it has "
                                 f"{', '.join((*self.ports, *self.streams))})")
        return self.directory / f"{port}.bin"

    def read_bytes(self, port: str) -> bytes:
        """The port's (or stream's) recorded bytes (the intact chunks), for small recordings
        and tests."""
        return b"".join(c.data for c in self.chunks(port))

    def _entries(self, port: str, data_size: int) -> Iterator[tuple]:
        """Validated index entries ``(line, offset, size, t_device, t_wall, read)`` (*read*: the
        read columns' fields as matched, parsed only where a chunk is made); a truncated tail
        ends it with ``(line, None, why, None, None, None)``."""
        index = self.directory / f"{port}.csv"
        try:
            fh = open(index, "rb")
        except OSError as e:
            raise RecordingError(f"{index}: {e.strerror}; the recording lacks the index of port "
                                 f"{port!r}: restore it or re-record") from None
        with fh:
            headers = [INDEX_HEADER] + [READS_HEADER] * (self.meta["version"] >= READS_VERSION)
            header = fh.readline(_MAX_INDEX_LINE + 1).rstrip(b"\r\n").decode("ascii", "replace")
            if header not in headers:
                raise RecordingError(f"{index}:1: the first line must be "
                                     f"{' or '.join(map(repr, headers))}; restore the index or "
                                     f"re-record")
            reads = self.reads[port] = header == READS_HEADER
            offset, last_dev, last_wall = 0, -1, -1

            def damaged(n: int, problem: str):
                raise RecordingError(f"{index}:{n}: {problem}; the index is damaged: "
                                     f"re-record, or restore {index.name}")
            for n, line in _numbered_lines(fh, _MAX_INDEX_LINE, damaged, first=2):
                if line is None:
                    yield n, None, "a partial last index line", None, None, None
                    return
                m = _ENTRY.fullmatch(line)  # one match a line: an hour's index is 600k lines
                if m is None or reads != (m[5] is not None or m[8] is not None):
                    damaged(n, _entry_problem(line, header))
                off, size, dev, wall, *read = m.groups()
                off, size = int(off), int(size)
                dev = int(dev) if dev else None
                wall = int(wall) if wall else None
                if off != offset:
                    damaged(n, f"offset {off} is not where the previous chunk ends ({offset})")
                if not 0 < size <= MAX_CHUNK:
                    damaged(n, f"size {size} is not in 1..{MAX_CHUNK}")
                if dev is not None:
                    if dev < last_dev:
                        damaged(n, f"t_device_ns {dev} is before the previous chunk's ({last_dev})")
                    last_dev = dev
                if wall is not None:
                    if wall < last_wall:
                        damaged(n, f"t_wall_ns {wall} is before the previous chunk's ({last_wall})")
                    last_wall = wall
                if off + size > data_size:
                    yield n, None, f"chunks past the end of {port}.bin ({data_size} bytes)", \
                        None, None, None
                    return
                yield n, off, size, dev, wall, read
                offset = off + size

    def _scan(self, port: str) -> None:
        data_path = self.path(port)
        try:
            data_size = data_path.stat().st_size
        except OSError as e:
            raise RecordingError(f"{data_path}: {e.strerror}; the recording lacks the data of "
                                 f"port {port!r}: restore it or re-record") from None
        count = used = 0
        for n, off, size, *_ in self._entries(port, data_size):
            if off is None:
                why = size
                index = self.directory / f"{port}.csv"
                if self.complete and not self.salvage:
                    raise RecordingError(
                        f"{index}:{n}: {why}: the recording is marked complete, so it is "
                        f"damaged; 'navtwin replay --salvage' replays the intact prefix")
                rest = self._index_entries(index) - count
                self.skipped[port] = {"chunks": rest, "bytes": data_size - used, "why": why}
                break
            count, used = count + 1, off + size
        else:
            if data_size > used:
                self.skipped[port] = {"chunks": 0, "bytes": data_size - used,
                                      "why": f"bytes of {port}.bin after its last indexed chunk"}
        self._intact[port], self.sizes[port] = count, used

    @staticmethod
    def _index_entries(path: Path) -> int:
        """Lines after the header, a partial last one included."""
        lines, last = 0, b"\n"
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 16), b""):
                lines, last = lines + block.count(b"\n"), block[-1:]
        return lines - 1 + (last != b"\n")

    def chunks(self, port: str) -> Iterator[Chunk]:
        """The port's (or stream's) intact chunks in order, read from the data file one at a
        time."""
        data_path = self.path(port)
        want = self._intact[port]
        if not want:
            return
        try:
            with open(data_path, "rb") as data:
                size = os.fstat(data.fileno()).st_size
                for i, (_, off, n, dev, wall, read) in enumerate(self._entries(port, size), 1):
                    blob = data.read(n) if off is not None else b""
                    if len(blob) != n:
                        raise RecordingError(f"{data_path}: changed while being read; read it "
                                             f"again when nothing writes to it")
                    yield Chunk(port, off, blob, dev, wall,
                                None if read[0] is None else Read(*map(int, read[:3])))
                    if i == want:
                        return
        except OSError as e:
            raise RecordingError(f"{data_path}: {e.strerror}; check the file and the disk") \
                from None

    def faults(self) -> list[dict]:
        """The fault ledger, validated (module docstring); [] without a faults.jsonl. A
        truncated tail (see the module docstring) is skipped in a recording that is not
        complete (``skipped["faults.jsonl"]``) and damage in a complete one, unless
        ``salvage``."""
        path = self.directory / FAULTS
        try:
            fh = open(path, "rb")
        except FileNotFoundError:
            return []
        except OSError as e:
            raise RecordingError(f"{path}: {e.strerror}; check the file and the disk") from None
        out: list[dict] = []
        def damaged(n: int, problem: str):
            raise RecordingError(f"{path}:{n}: {problem}; the fault ledger is damaged: "
                                 f"re-record, or restore {FAULTS}")
        with fh:
            for n, line in _numbered_lines(fh, _MAX_FAULT_LINE, damaged):
                def bad(problem: str):
                    damaged(n, problem)
                if line is None:
                    self._tail(path, n, "a partial last line", len(out) + 1)
                    break
                try:
                    entry = json.loads(line.decode("utf-8"))
                except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
                    bad(f"not a JSON object ({type(e).__name__})")
                problem = self._fault_problem(entry)
                if problem:
                    bad(problem)
                if entry["port"] is not None and entry["end"] is not None \
                        and entry["direction"] != "to_device" \
                        and entry["end"] > self.sizes[entry["port"]]:
                    # an entry is buffered just before its bytes: a killed run may have the
                    # entry and not yet the bytes
                    self._tail(path, n, f"entries past the end of {entry['port']}.bin",
                               _lines(path) - n + 1)
                    break
                out.append(entry)
        return out

    def _tail(self, path: Path, n: int, why: str, entries: int) -> None:
        if self.complete and not self.salvage:
            raise RecordingError(f"{path}:{n}: {why}: the recording is marked complete, so it "
                                 f"is damaged; 'navtwin replay --salvage' uses the intact prefix")
        self.skipped[FAULTS] = {"chunks": entries, "bytes": 0, "why": why}

    def _fault_problem(self, e) -> str | None:
        """What is wrong with a ledger entry, or None."""
        def integer(v) -> bool:
            return type(v) is int

        if not isinstance(e, dict):
            return f"an entry is {type(e).__name__}, not an object"
        missing = [k for k in ("kind", "fault", "port", "direction", "t_ns", "start", "end")
                   if k not in e]
        if missing:
            return f"an entry lacks {', '.join(missing)}"
        if not isinstance(e["kind"], str) or not e["kind"]:
            return f"kind {e['kind']!r} is not a name"
        if e["fault"] is not None and not (integer(e["fault"]) and e["fault"] >= 0):
            return f"fault {e['fault']!r} is not an index >= 0 or null"
        if e["port"] is not None and e["port"] not in self.ports:
            return f"port {e['port']!r} is not a port of the recording"
        if e["direction"] is not None and e["direction"] not in DIRECTIONS:
            return f"direction {e['direction']!r} is not one of {', '.join(DIRECTIONS)} or null"
        if not integer(e["t_ns"]):
            return f"t_ns {e['t_ns']!r} is not an integer"
        start, end = e["start"], e["end"]
        if (start is None) != (end is None) or (start is not None and not (
                integer(start) and integer(end) and 0 <= start <= end)):
            return f"start {start!r}, end {end!r} are not integers 0 <= start <= end or both null"
        return None

    def merged(self, ports: list[str] | None = None, clock: str = "t_wall_ns") -> Iterator[Chunk]:
        """Chunks of several ports in time order (ties: port name order) by *clock*."""
        def keyed(i: int, port: str):
            for c in self.chunks(port):
                yield getattr(c, clock) or 0, i, c.offset, c

        streams = [keyed(i, p) for i, p in enumerate(sorted(ports or self.ports))]
        for *_, chunk in heapq.merge(*streams):
            yield chunk

    def skipped_line(self) -> str | None:
        """One line on what a replay of this recording leaves out, or None."""
        if self.complete and not self.skipped:
            return None
        parts = [f"{p}: {s['chunks']} chunks, {s['bytes']} bytes ({s['why']})"
                 for p, s in self.skipped.items()]
        state = ("is incomplete (its run was killed or a write failed)" if not self.complete
                 else "is damaged and was salvaged" if self.salvage else "has extra bytes")
        return (f"{self.directory} {state}: using the intact prefix; skipped "
                f"{'; '.join(parts) if parts else 'nothing'}")
