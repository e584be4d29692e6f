"""The live host: read the lab's ports, record what arrives, process it, write estimates.

Each port is opened with pyserial's ``serial_for_url`` (a device path such as /dev/ttyUSB0
or one of the emulator's PTY links, or ``socket://``, ``rfc2217://``, ``spy://``) and
owned by a reader thread, which sends ``(port, bytes, read time)`` to one queue. The
caller's thread takes the chunks in queue order, stamps each with its arrival time
``max(read ns - start ns, previous stamp + 1)`` (one counter for all ports, so stamps are
unique and increasing), records it, and feeds it to the :class:`navtwin.host.pipeline.Pipeline`.
The recording therefore holds exactly what was processed, in order: ``navtwin replay``
gives the same estimates. Each read carries its read columns (protocols.recording.Read),
counted by its reader as it reads, not by the recorder: a read lost or reordered between the
port and the disk shows in them, and ``navtwin audit`` fails on it.

The recording is flushed every ``FLUSH_S`` (a kill loses at most ~1 s of it). A write that
fails, to the recording or to the estimate output (disk full, EIO, a file size limit), ends
the run: the recording is closed with what was written, the summary is still written, and
:attr:`Service.error` holds the one-line reason. A broken pipe on the output is not such a
failure: it ends the run quietly (``BrokenPipeError``), as the reader is gone.

Ports are opened exclusively (``flock``, as picocom, tio and minicom do), so a well-behaved
second client is refused instead of splitting the bytes. A read that fails (device
unplugged, PTY link gone, EIO, socket closed) closes the port; its reader reopens it every
``RETRY_S`` by wall clock until it is back. A read that found no data although the line was
readable, on a tty that is not hung up, means another reader took the bytes: it is counted
(``contended``) and the port stays open. The pipeline keeps its state meanwhile: only which
bytes arrive, not how they are processed, depends on it.

An emulator's link (:mod:`navtwin.protocols.linkdir`) is opened only while the emulator that made it
holds its directory's lock: once it is gone the link's ``/dev/pts/N`` may be another
program's terminal. The reader then says ``emulator_gone`` once and waits for an emulator to
take the directory again.
"""
from __future__ import annotations

import errno
import os
import queue
import select
import termios
import threading
import time
from pathlib import Path
from typing import Callable, TextIO

import serial

from navtwin.protocols import __version__
from navtwin.protocols.linkdir import LOCK, emulator_alive, navtwin_link_dir
from navtwin.protocols import ports as lab_ports
from navtwin.protocols.ports import DEFAULT_BAUD
from navtwin.protocols.recording import (FLUSH_S, Read, RecordingWriteError, RecordingWriter,
                                         write_failure)

from .config import HostConfig
from .output import Latency, estimate_line, info_line, innovation_line
from .pipeline import Pipeline

READ_TIMEOUT_S = 0.1  # how often a reader looks at the stop flag
RETRY_S = 0.5
MAX_CHUNK = 1 << 16
TX_PORT = "xbee.tx"  # what the host sent to the coordinator, recorded for completeness
HOST_SOURCE = "navtwin host"  # a host recording's meta "source"


class OutputError(Exception):
    """The estimate (or innovation) output cannot be written: one line naming it and the fix;
    ``setting`` names that output (``out``, ``innovations``)."""

    def __init__(self, message: str, setting: str = "out") -> None:
        super().__init__(message)
        self.setting = setting


class StartError(Exception):
    """A port that cannot be opened or a recording that cannot be made at start: one line
    naming it and the fix."""


class EmulatorGone(StartError):
    """An emulator link whose emulator no longer holds the link directory's lock."""

    def __init__(self, url: str, link_dir: Path) -> None:
        super().__init__(f"{url}: the emulator that made this link is gone (nothing holds "
                         f"{link_dir / LOCK}); start navtwin emulate --link-dir {link_dir}")
        self.link_dir = link_dir


def open_port(url: str, baud: int) -> serial.SerialBase:
    """Open *url*; an emulator link only while its emulator lives. Raises :class:`StartError`
    for what the user must fix (the lock of another program, the emulator gone), pyserial's
    or the OS's error otherwise."""
    link_dir = navtwin_link_dir(url)
    if link_dir is not None and not emulator_alive(link_dir):
        raise EmulatorGone(url, link_dir)
    try:  # exclusive: ignored by URLs other than device paths
        return serial.serial_for_url(url, baudrate=baud, timeout=READ_TIMEOUT_S, exclusive=True)
    except serial.SerialException as e:
        if e.errno == errno.EWOULDBLOCK:  # pyserial's flock(LOCK_EX | LOCK_NB) was refused
            raise StartError(f"{url}: another program has it open exclusively (picocom, tio, "
                             f"minicom...); close that program") from None
        raise


def hung_up(ser: serial.SerialBase) -> bool:
    """Whether *ser*'s line is gone: POLLHUP or EIO on a tty (a USB adapter unplugged, a PTY
    whose master closed). True for what is not a tty: its error is not a second reader's."""
    fd = getattr(ser, "fd", None)
    if fd is None:
        return True
    try:
        p = select.poll()
        p.register(fd, select.POLLIN)
        if any(ev & (select.POLLHUP | select.POLLERR | select.POLLNVAL) for _, ev in p.poll(0)):
            return True
        termios.tcgetattr(fd)
    except (OSError, termios.error, ValueError):
        return True
    return False


def read_chunk(ser: serial.SerialBase) -> bytes:
    """What has arrived, waiting up to the port's timeout for it. On a tty everything waiting
    is taken in one ``read(2)`` once the line is readable, so a second reader woken by the
    same bytes finds them gone instead of taking all but the first, and a chunk is always
    contiguous in the line's stream (pyserial's ``read(n)`` loops over several reads, between
    which a second reader can take bytes: one soak chunk had a frame, then a byte from five
    frames later). A readable tty with nothing to read (another reader was first, or a
    hang-up) raises, as pyserial does. Elsewhere (``in_waiting`` is 0/1 on sockets) the
    first byte is waited for and the rest taken without waiting; a port that goes away after
    some of them (a socket's peer closed) gives those bytes, and raises at the next read."""
    fd = getattr(ser, "fd", None)
    if fd is not None:
        if not select.select([fd], [], [], ser.timeout)[0]:
            return b""
        try:
            data = os.read(fd, MAX_CHUNK)  # pyserial keeps the fd non-blocking
        except BlockingIOError:
            data = b""
        if not data:
            raise serial.SerialException("readable but no data waiting")
        return data
    data = ser.read(1)
    try:
        while data and len(data) < MAX_CHUNK and (n := ser.in_waiting):
            data += ser.read(n)
    except serial.SerialException:
        pass  # the bytes before the end are the stream's: the next read meets the end again
    return data


class PortReader(threading.Thread):
    """Owns one port: reads into the queue; on failure closes, reports, reopens. Events go to
    the queue as ``(event, port, body, read ns)``; data as ``("data", port, (bytes, Read),
    read ns)``."""

    def __init__(self, name: str, url: str, baud: int, ser: serial.SerialBase,
                 chunks: queue.SimpleQueue, stop: threading.Event) -> None:
        super().__init__(name=f"navtwin-host-{name}", daemon=True)
        self.port, self.url, self.baud = name, url, baud
        self._ser: serial.SerialBase | None = ser
        self._chunks = chunks
        self._quit = stop
        self._lock = threading.Lock()
        self.state = "open"  # "open", "down", or "emulator_gone" (down, and not reopened)
        self.reconnects = 0
        self.contended = 0  # reads that found the bytes taken by another reader
        self.read_bytes = 0  # bytes read from the port so far, over every reopen
        self.tx_dropped = 0

    def _event(self, event: str, **body) -> None:
        self._chunks.put((event, self.port, body, time.monotonic_ns()))

    def run(self) -> None:
        try:
            while not self._quit.is_set():
                ser = self._ser
                if ser is None:
                    try:
                        ser = open_port(self.url, self.baud)
                    except EmulatorGone as e:
                        if self.state != "emulator_gone":
                            self.state = "emulator_gone"
                            self._event("emulator_gone", link_dir=str(e.link_dir))
                        self._quit.wait(RETRY_S)
                        continue
                    except (serial.SerialException, OSError, ValueError, StartError):
                        self.state = "down"
                        self._quit.wait(RETRY_S)
                        continue
                    with self._lock:
                        self._ser, self.state = ser, "open"
                    self.reconnects += 1
                    self._event("port_up")
                try:
                    data = read_chunk(ser)
                except (serial.SerialException, OSError) as e:
                    if not hung_up(ser):
                        self.contended += 1
                        continue
                    self._close()
                    self._event("port_down", error=str(e))
                    self._quit.wait(RETRY_S)
                    continue
                if data:
                    read = Read(self.read_bytes, self.reconnects, self.contended)
                    self.read_bytes += len(data)
                    self._chunks.put(("data", self.port, (data, read), time.monotonic_ns()))
        finally:
            self._close()

    def _close(self) -> None:
        with self._lock:
            ser, self._ser, self.state = self._ser, None, "down"
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass

    def write(self, data: bytes) -> bool:
        """Send *data* if the port is open; False (and counted) if it could not be sent."""
        with self._lock:
            try:
                if self._ser is not None:
                    self._ser.write(data)
                    return True
            except (serial.SerialException, OSError):
                pass
        self.tx_dropped += 1
        return False


def recording_meta(config: HostConfig, filters: tuple[str, ...], escaped: bool,
                   ports: dict[str, str], baud: int) -> dict:
    """A host recording's meta: everything ``navtwin replay`` needs to redo the run."""
    return {"source": HOST_SOURCE, "navtwin": __version__,
            "host": {"config": config.to_dict(), "filters": list(filters), "escaped": escaped,
                     "inputs": [p for p in lab_ports.host_inputs() if p in ports]},
            "clock": "t_wall_ns = arrival, monotonic ns since the host started",
            "ports": {**{p: {"url": u, "baud": baud} for p, u in ports.items()},
                      **{TX_PORT: {"of": p} for p in written_ports(ports)[:1]}}}


def written_ports(ports) -> list[str]:
    """Those of *ports* whose device reads what the host writes (the coordinator's)."""
    return [p for p in ports if lab_ports.get(p).host_writes]


class Service:
    """One live run: ports -> recording + pipeline -> estimate lines."""

    def __init__(self, ports: dict[str, str], config: HostConfig, filters: tuple[str, ...], *,
                 out: TextIO, escaped: bool = True, baud: int = DEFAULT_BAUD,
                 record: str | os.PathLike | None = None, status: TextIO | None = None,
                 status_period_s: float = 2.0, make_estimator=None,
                 on_lines: Callable[[str, int, int], None] | None = None,
                 innovations: TextIO | None = None) -> None:
        readable = lab_ports.host_inputs()
        unknown = set(ports) - set(readable)
        if unknown or not ports:
            raise ValueError(f"ports must be some of {', '.join(readable)}")
        self.ports = {p: ports[p] for p in readable if p in ports}
        self.config, self.filters = config, tuple(filters)
        self._frame = config.output_frame  # [output] geodetic: lat, lon, h in each line
        self.out, self.status, self.status_period_s = out, status, status_period_s
        # on_lines(port, bytes of that port processed, monotonic ns) after each batch of lines
        self.on_lines = on_lines
        self.escaped, self.baud = escaped, baud
        self.innovations = innovations  # the fusion tracks' innovation lines, if given
        # the port the host's AT queries go to (the pipeline makes them only when it reads one)
        self._written = next(iter(written_ports(self.ports)), None)
        self.pipeline = Pipeline(config, self.filters, inputs=tuple(self.ports), escaped=escaped,
                                 make_estimator=make_estimator,
                                 on_innovation=None if innovations is None else self._innovation)
        self.latency = Latency()
        self.record_dir = None if record is None else Path(record)
        self.recorder: RecordingWriter | None = None
        self.error: RecordingWriteError | OutputError | None = None  # what ended the run
        self.lines = 0
        self.chunks = 0
        self.bytes = dict.fromkeys(self.ports, 0)
        self._readers: dict[str, PortReader] = {}
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop_readers = threading.Event()
        self._last_stamp = -1
        self._t0 = 0
        self._prev: dict = {}
        # per vehicle number: its estimator's re-init counts last reported, and their total
        self._reinit: dict[int, dict] = {}
        self._reinit_seen = {v.number: 0 for v in self.pipeline.vehicles}
        self.started = threading.Event()  # set once the ports are open and being read

    # -- setup ---------------------------------------------------------------------------
    def meta(self) -> dict:
        return recording_meta(self.config, self.filters, self.escaped, self.ports, self.baud)

    def _open(self) -> dict[str, serial.SerialBase]:
        opened: dict[str, serial.SerialBase] = {}
        try:
            for name, url in self.ports.items():
                try:
                    opened[name] = open_port(url, self.baud)
                except StartError as e:
                    raise StartError(f"{name}: cannot open {e}") from None
                except (serial.SerialException, OSError, ValueError) as e:
                    raise StartError(f"{name}: cannot open {url}: {e}; check the device path "
                                    f"or URL (socket://, rfc2217://, spy://)") from None
        except StartError:
            for s in opened.values():
                s.close()
            raise
        return opened

    def _start_recording(self) -> None:
        # a new or empty directory, never through a symbolic link (the writer checks)
        try:
            self.recorder = RecordingWriter(self.record_dir, self.meta(), reads=True)
        except RecordingWriteError as e:
            raise StartError(f"record: {e}") from None

    # -- run -----------------------------------------------------------------------------
    def run(self, stop: threading.Event | None = None, duration_s: float | None = None) -> dict:
        """Until *stop* is set (or *duration_s* of wall time); returns the summary."""
        stop = stop or threading.Event()
        opened = self._open()
        if self.record_dir is not None:
            try:
                self._start_recording()
            except StartError:
                for ser in opened.values():
                    ser.close()
                raise
        self._t0 = time.monotonic_ns()
        if self.recorder is not None:  # host time 0 on CLOCK_MONOTONIC, in the final meta
            self.recorder.meta["t0_monotonic_ns"] = self._t0
        for name, ser in opened.items():
            r = self._readers[name] = PortReader(name, self.ports[name], self.baud, ser,
                                                 self._queue, self._stop_readers)
            r.start()
        self._info("status", {"event": "started", "t0_monotonic_ns": self._t0, "ports": self.ports,
                              "filters": list(self.filters), "config": self.config.name})
        self.started.set()
        period_ns = int(self.status_period_s * 1e9)
        next_status = self._t0 + period_ns
        end = None if duration_s is None else self._t0 + int(duration_s * 1e9)
        try:
            self._loop(stop, period_ns, next_status, end)
        except (RecordingWriteError, OutputError) as e:
            self.error = e
        finally:
            self._stop_readers.set()
            for r in self._readers.values():
                r.join()
            if self.recorder is not None:
                try:
                    self.recorder.close()
                except RecordingWriteError as e:
                    self.error = self.error or e
        if not isinstance(self.error, OutputError):
            try:
                self._emit(self.pipeline.finish(), None, None)
            except OutputError as e:
                self.error = self.error or e
        summary = self.summary()
        self._info("summary", summary)
        return summary

    def _loop(self, stop: threading.Event, period_ns: int, next_status: int,
              end: int | None) -> None:
        flush_ns = int(FLUSH_S * 1e9)
        next_flush = self._t0 + flush_ns
        while not stop.is_set():
            try:
                kind, name, data, t_read = self._queue.get(timeout=0.05)
            except queue.Empty:
                kind = None
            if kind == "data":
                self._process(name, *data, t_read)
            elif kind is not None:
                self._info("status", {"event": kind, "port": name, **data})
            now = time.monotonic_ns()
            if now >= next_status:
                self._status(now)
                next_status = now + period_ns
            if self.recorder is not None and now >= next_flush:
                self.recorder.flush()
                next_flush = now + flush_ns
            if end is not None and now >= end:
                break

    def _process(self, name: str, data: bytes, read: Read, t_read: int) -> None:
        stamp = max(t_read - self._t0, self._last_stamp + 1)
        self._last_stamp = stamp
        self.chunks += 1
        self.bytes[name] += len(data)
        if self.recorder is not None:
            self.recorder.port(name).write(data, t_wall_ns=stamp, read=read)
        self._emit(self.pipeline.feed(name, data, stamp), name, t_read)
        for event in self.pipeline.take_events():  # the coordinator's API mode changed
            self._info("status", event)
        for v in self.pipeline.vehicles:
            if v.estimator.reinit_count != self._reinit_seen[v.number]:
                self._reinit_event(v)
        tx = self.pipeline.take_tx()
        if tx and self._readers[self._written].write(tx) and self.recorder is not None:
            self.recorder.port(TX_PORT).write(tx, t_wall_ns=stamp)

    def _emit(self, estimates: list, port: str | None, t_read: int | None) -> None:
        if not estimates:
            return
        try:
            self.out.write("".join(estimate_line(e, self._frame) for e in estimates))
            self.out.flush()
        except BrokenPipeError:
            raise
        except OSError as e:
            raise OutputError(write_failure(getattr(self.out, "name", "the output"), e)) from None
        self.lines += len(estimates)
        done = time.monotonic_ns()
        if port is not None:
            self.latency.add(done - t_read)
            if self.on_lines is not None:
                self.on_lines(port, self.bytes[port], done)

    def _innovation(self, *fields) -> None:
        try:
            self.innovations.write(innovation_line(*fields))
        except OSError as e:
            raise OutputError(write_failure(getattr(self.innovations, "name", "the innovations"), e),
                              "innovations") from None

    # -- reporting ---------------------------------------------------------------------------
    def _info(self, kind: str, body: dict) -> None:
        if self.status is not None:
            self.status.write(info_line(kind, body))
            self.status.flush()

    def _reinit_event(self, v) -> None:
        """A track of vehicle *v* re-initialised (a discontinuity, host.estimator): which, why,
        and the totals."""
        st = v.estimator.stats()
        last = self._reinit.get(v.number, {})
        new = {}
        for track, causes in st["reinit"].items():
            diff = {c: n - last.get(track, {}).get(c, 0) for c, n in causes.items()}
            if any(diff.values()):
                new[track] = {c: n for c, n in diff.items() if n}
        self._reinit[v.number], self._reinit_seen[v.number] = st["reinit"], v.estimator.reinit_count
        self._info("status", {"event": "reinit", "vehicle": v.number, "filter_time": v.t,
                              "new": new, "reinit": st["reinit"], "pending": st["reinit_pending"]})

    def _status(self, now: int) -> None:
        st = self.pipeline.stats()
        dt = (now - self._prev.get("now", self._t0)) / 1e9
        rates = {}
        for p, r in self._readers.items():
            frames = st["ports"][p]["frames"]
            rates[p] = {"state": r.state,
                        "frames_per_s": round((frames - self._prev.get(p, 0)) / dt, 1),
                        "bytes": st["ports"][p]["bytes"], "contended": r.contended}
            self._prev[p] = frames
        imu, ranges = st["counts"].get("imu", 0), st["counts"].get("reports", 0)
        body = {"t_s": round((now - self._t0) / 1e9, 3), "ports": rates,
                "imu": imu, "imu_per_s": round((imu - self._prev.get("imu", 0)) / dt, 1),
                "reports": ranges,
                "reports_per_s": round((ranges - self._prev.get("reports", 0)) / dt, 1),
                "errors": {p: v["errors"] for p, v in st["ports"].items() if v["errors"]},
                "link_dbm": st["link_dbm"], "latency": self.latency.period(),
                "estimates": self.lines, "held": st["held"],
                "reinit": {str(n): r for n, r in self._reinit.items() if r},
                # IMU gaps by vehicle: bridged (filter state kept) or re-initialised
                "imu_gaps": {str(v.number): g for v in self.pipeline.vehicles
                             if any((g := v.estimator.imu_gaps()).values())}}
        self._prev.update(now=now, imu=imu, reports=ranges)
        self._info("status", body)

    def summary(self) -> dict:
        return {"chunks": self.chunks, "lines": self.lines, "t0_monotonic_ns": self._t0,
                "reconnects": {p: r.reconnects for p, r in self._readers.items()},
                "contended": {p: r.contended for p, r in self._readers.items()},
                "tx_dropped": sum(r.tx_dropped for r in self._readers.values()),
                "latency": self.latency.overall(), **self.pipeline.stats(),
                **({"recording": str(self.record_dir)} if self.record_dir else {}),
                **({"error": str(self.error)} if self.error else {})}
