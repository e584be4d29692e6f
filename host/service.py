"""The live host: read the lab's ports, record what arrives, process it, write estimates.

Each port is opened with pyserial's ``serial_for_url`` (a device path such as /dev/ttyUSB0
or one of the emulator's PTY links, or ``socket://``, ``rfc2217://``, ``spy://``) and
owned by a reader thread, which sends ``(port, bytes, read time)`` to one queue. The
caller's thread takes the chunks in queue order, stamps each with its arrival time
``max(read ns - start ns, previous stamp + 1)`` (one counter for all ports, so stamps are
unique and increasing), records it, and feeds it to the :class:`host.pipeline.Pipeline`.
The recording therefore holds exactly what was processed, in order: ``navtwin replay``
gives the same estimates.

A read that fails (device unplugged, PTY link gone, EIO, socket closed) closes the port;
its reader reopens it every ``RETRY_S`` by wall clock until it is back. The pipeline keeps
its state meanwhile: only which bytes arrive, not how they are processed, depends on it.
"""
from __future__ import annotations

import os
import queue
import threading
import time
from pathlib import Path
from typing import Callable, TextIO

import serial

from protocols import __version__
from protocols.recording import RecordingWriter

from .config import HostConfig
from .output import Latency, estimate_line, info_line
from .pipeline import INPUTS, Pipeline

READ_TIMEOUT_S = 0.1  # how often a reader looks at the stop flag
RETRY_S = 0.5
MAX_CHUNK = 1 << 16
TX_PORT = "xbee.tx"  # what the host sent to the coordinator, recorded for completeness
HOST_SOURCE = "navtwin host"  # a host recording's meta "source"


class StartError(Exception):
    """A port that cannot be opened or a recording that cannot be made at start: one line
    naming it and the fix."""


def open_port(url: str, baud: int) -> serial.SerialBase:
    return serial.serial_for_url(url, baudrate=baud, timeout=READ_TIMEOUT_S)


def read_chunk(ser: serial.SerialBase) -> bytes:
    """What has arrived: waits up to the port's timeout for a first byte, then takes the
    rest without waiting (``in_waiting`` is exact on ttys, 0/1 on sockets)."""
    data = ser.read(1)
    if data:
        while len(data) < MAX_CHUNK and (n := ser.in_waiting):
            data += ser.read(n)
    return data


class PortReader(threading.Thread):
    """Owns one port: reads into the queue; on failure closes, reports, reopens."""

    def __init__(self, name: str, url: str, baud: int, ser: serial.SerialBase,
                 chunks: queue.SimpleQueue, stop: threading.Event) -> None:
        super().__init__(name=f"navtwin-host-{name}", daemon=True)
        self.port, self.url, self.baud = name, url, baud
        self._ser: serial.SerialBase | None = ser
        self._chunks = chunks
        self._quit = stop
        self._lock = threading.Lock()
        self.state = "open"
        self.reconnects = 0
        self.tx_dropped = 0

    def run(self) -> None:
        try:
            while not self._quit.is_set():
                ser = self._ser
                if ser is None:
                    try:
                        ser = open_port(self.url, self.baud)
                    except (serial.SerialException, OSError, ValueError):
                        self._quit.wait(RETRY_S)
                        continue
                    with self._lock:
                        self._ser, self.state = ser, "open"
                    self.reconnects += 1
                    self._chunks.put(("up", self.port, b"", time.monotonic_ns()))
                try:
                    data = read_chunk(ser)
                except (serial.SerialException, OSError) as e:
                    self._close()
                    self._chunks.put(("down", self.port, str(e).encode(), time.monotonic_ns()))
                    self._quit.wait(RETRY_S)
                    continue
                if data:
                    self._chunks.put(("data", self.port, data, time.monotonic_ns()))
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
                     "inputs": [p for p in INPUTS if p in ports]},
            "clock": "t_wall_ns = arrival, monotonic ns since the host started",
            "ports": {**{p: {"url": u, "baud": baud} for p, u in ports.items()},
                      **({TX_PORT: {"of": "xbee"}} if "xbee" in ports else {})}}


class Service:
    """One live run: ports -> recording + pipeline -> estimate lines."""

    def __init__(self, ports: dict[str, str], config: HostConfig, filters: tuple[str, ...], *,
                 out: TextIO, escaped: bool = True, baud: int = 115200,
                 record: str | os.PathLike | None = None, status: TextIO | None = None,
                 status_period_s: float = 2.0, estimator=None,
                 on_lines: Callable[[str, int, int], None] | None = None) -> None:
        unknown = set(ports) - set(INPUTS)
        if unknown or not ports:
            raise ValueError(f"ports must be some of {', '.join(INPUTS)}")
        self.ports = {p: ports[p] for p in INPUTS if p in ports}
        self.config, self.filters = config, tuple(filters)
        self.out, self.status, self.status_period_s = out, status, status_period_s
        # on_lines(port, bytes of that port processed, monotonic ns) after each batch of lines
        self.on_lines = on_lines
        self.escaped, self.baud = escaped, baud
        self.pipeline = Pipeline(config, self.filters, inputs=tuple(self.ports), escaped=escaped,
                                 estimator=estimator)
        self.latency = Latency()
        self.record_dir = None if record is None else Path(record)
        self.recorder: RecordingWriter | None = None
        self.lines = 0
        self.chunks = 0
        self.bytes = dict.fromkeys(self.ports, 0)
        self._readers: dict[str, PortReader] = {}
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop_readers = threading.Event()
        self._last_stamp = -1
        self._t0 = 0
        self._prev: dict = {}
        self._reinit: dict = {}  # the estimator's re-init counts last reported
        self._reinit_seen = 0  # and their total
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
                except (serial.SerialException, OSError, ValueError) as e:
                    raise StartError(f"cannot open --{name} {url}: {e}; check the device path "
                                    f"or URL (socket://, rfc2217://, spy://)") from None
        except StartError:
            for s in opened.values():
                s.close()
            raise
        return opened

    def _start_recording(self) -> None:
        d = self.record_dir
        if d.exists() and (not d.is_dir() or any(d.iterdir())):
            raise StartError(f"--record {d}: exists and is not an empty directory; "
                             f"choose a new directory")
        try:
            self.recorder = RecordingWriter(d, self.meta())
            for name in self.ports:
                self.recorder.port(name)
            if "xbee" in self.ports:
                self.recorder.port(TX_PORT)
            self.recorder.write_meta()
        except OSError as e:
            raise StartError(f"--record {d}: {e.strerror}; choose a writable directory") from None

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
        for name, ser in opened.items():
            r = self._readers[name] = PortReader(name, self.ports[name], self.baud, ser,
                                                 self._queue, self._stop_readers)
            r.start()
        self._info("status", {"event": "started", "ports": self.ports,
                              "filters": list(self.filters), "config": self.config.name})
        self.started.set()
        period_ns = int(self.status_period_s * 1e9)
        next_status = self._t0 + period_ns
        end = None if duration_s is None else self._t0 + int(duration_s * 1e9)
        try:
            while not stop.is_set():
                try:
                    kind, name, data, t_read = self._queue.get(timeout=0.05)
                except queue.Empty:
                    kind = None
                if kind == "data":
                    self._process(name, data, t_read)
                elif kind is not None:
                    self._info("status", {"event": f"port_{kind}", "port": name,
                                          **({"error": data.decode()} if data else {})})
                now = time.monotonic_ns()
                if now >= next_status:
                    self._status(now)
                    if self.recorder is not None:
                        self.recorder.flush()
                    next_status = now + period_ns
                if end is not None and now >= end:
                    break
        finally:
            self._stop_readers.set()
            for r in self._readers.values():
                r.join()
            if self.recorder is not None:
                self.recorder.close()
        self._emit(self.pipeline.finish(), None, None)
        self.out.flush()
        summary = self.summary()
        self._info("summary", summary)
        return summary

    def _process(self, name: str, data: bytes, t_read: int) -> None:
        stamp = max(t_read - self._t0, self._last_stamp + 1)
        self._last_stamp = stamp
        self.chunks += 1
        self.bytes[name] += len(data)
        if self.recorder is not None:
            self.recorder.port(name).write(data, t_wall_ns=stamp)
        self._emit(self.pipeline.feed(name, data, stamp), name, t_read)
        if self.pipeline.estimator.reinit_count != self._reinit_seen:
            self._reinit_event()
        tx = self.pipeline.take_tx()
        if tx and self._readers["xbee"].write(tx) and self.recorder is not None:
            self.recorder.port(TX_PORT).write(tx, t_wall_ns=stamp)

    def _emit(self, estimates: list, port: str | None, t_read: int | None) -> None:
        if not estimates:
            return
        self.out.write("".join(map(estimate_line, estimates)))
        self.out.flush()
        self.lines += len(estimates)
        done = time.monotonic_ns()
        if port is not None:
            self.latency.add(done - t_read)
            if self.on_lines is not None:
                self.on_lines(port, self.bytes[port], done)

    # -- reporting ---------------------------------------------------------------------------
    def _info(self, kind: str, body: dict) -> None:
        if self.status is not None:
            self.status.write(info_line(kind, body))
            self.status.flush()

    def _reinit_event(self) -> None:
        """A track re-initialised (a discontinuity, host.estimator): which, why, and the totals."""
        st = self.pipeline.estimator.stats()
        new = {}
        for track, causes in st["reinit"].items():
            diff = {c: n - self._reinit.get(track, {}).get(c, 0) for c, n in causes.items()}
            if any(diff.values()):
                new[track] = {c: n for c, n in diff.items() if n}
        self._reinit, self._reinit_seen = st["reinit"], self.pipeline.estimator.reinit_count
        self._info("status", {"event": "reinit", "filter_time": self.pipeline.t, "new": new,
                              "reinit": st["reinit"], "pending": st["reinit_pending"]})

    def _status(self, now: int) -> None:
        st = self.pipeline.stats()
        dt = (now - self._prev.get("now", self._t0)) / 1e9
        rates = {}
        for p, r in self._readers.items():
            frames = st["ports"][p]["frames"]
            rates[p] = {"state": r.state,
                        "frames_per_s": round((frames - self._prev.get(p, 0)) / dt, 1),
                        "bytes": st["ports"][p]["bytes"]}
            self._prev[p] = frames
        imu, ranges = st["counts"].get("imu", 0), st["counts"].get("reports", 0)
        body = {"t_s": round((now - self._t0) / 1e9, 3), "ports": rates,
                "imu": imu, "imu_per_s": round((imu - self._prev.get("imu", 0)) / dt, 1),
                "reports": ranges,
                "reports_per_s": round((ranges - self._prev.get("reports", 0)) / dt, 1),
                "errors": {p: v["errors"] for p, v in st["ports"].items() if v["errors"]},
                "link_dbm": st["link_dbm"], "latency": self.latency.period(),
                "estimates": self.lines, "held": st["held"], "reinit": self._reinit}
        self._prev.update(now=now, imu=imu, reports=ranges)
        self._info("status", body)

    def summary(self) -> dict:
        return {"chunks": self.chunks, "lines": self.lines, "t0_monotonic_ns": self._t0,
                "reconnects": {p: r.reconnects for p, r in self._readers.items()},
                "tx_dropped": sum(r.tx_dropped for r in self._readers.values()),
                "latency": self.latency.overall(), **self.pipeline.stats(),
                "estimator": self.pipeline.estimator.stats(),
                **({"recording": str(self.record_dir)} if self.record_dir else {})}
