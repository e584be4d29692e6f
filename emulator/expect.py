"""Expectations on a running lab's ports: wait for a frame, assert none comes, or silence.

A :class:`PortWatch` reads one port as a client would (opens its stable link, raw 8N1 at the
port's rate, decodes with the port's declared format in the scenario's API mode, see
protocols.match) and waits *on the data* with a deadline: ``select`` on the PTY, never a
sleep. Hang-ups (``lab.unplug``) close its end; it opens the link again once it is back.

Time. In a real-time lab a timeout is wall time. In virtual time (``--speed max`` or a
factor) it is device time: the lab's own clock, ``virtual_s`` in the control socket's
``status`` (the same for every port, unlike a SINS frame's counter, which only the SINS
stream carries and a board reset restarts). Everything readable is read before the clock is
judged, and the clock is read at least every :data:`CLOCK_S` of wall time while waiting. At a
factor the lab writes each chunk at its device time, so a window holds to that much wall
time; at ``--speed max`` the lab writes a block of device time (runner.MAX_BLOCK_NS, 1 s) at
once, ahead of its clock, so a window's edges hold to about a block.
"""
from __future__ import annotations

import errno
import os
import select
import termios
import threading
import time
import tty

from ..protocols import ports
from ..protocols.match import Match, Stream
from ..protocols.ports import DEFAULT_BAUD

CLOCK_S = 0.05  # wall time between two readings of a virtual-time lab's clock
CHUNK = 65536


class ExpectError(AssertionError):
    """An expectation on a lab port failed; the message says what was awaited, where, for how
    long, and the last frames decoded."""


class ExpectTimeout(ExpectError):
    """``expect``: the awaited bytes or frame did not come in time."""


class Unexpected(ExpectError):
    """``expect_none`` saw a match, or ``idle`` saw bytes."""


class PortWatch:
    """One port of *lab* (emulator.api.Lab), read for expectations."""

    def __init__(self, lab, port: str, scenario) -> None:
        if port not in lab.ports:
            raise ValueError(f"port: the lab has no port {port!r}; use one of "
                             f"{', '.join(lab.ports)}")
        settings = scenario.ports.get(port, {})
        self.lab, self.port = lab, port
        self.baud = settings.get("baud", DEFAULT_BAUD)
        self._stream_args = dict(format=ports.get(port).format,
                                 escaped=ports.escaped(settings),
                                 gyro_range=scenario.imu.gyro_range_dps)
        self.stream = Stream(**self._stream_args)
        self._taps: list[Stream] = []
        self.fd: int | None = None
        self._open()

    def tap(self) -> Stream:
        """Another stream of this port's bytes, with its own position (a ``--fail-on``
        beside the expects), fed as :attr:`stream` is."""
        tap = Stream(**self._stream_args)
        self._taps.append(tap)
        return tap

    # -- the port as a client reads it -----------------------------------------------------
    def _open(self) -> None:
        link = self.lab.ports.get(self.port)
        try:
            fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:  # unplugged: no link until it is plugged back
            return
        tty.setraw(fd)
        attrs = termios.tcgetattr(fd)
        attrs[4] = attrs[5] = getattr(termios, f"B{self.baud}")
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
        self.fd = fd

    def _hang_up(self) -> None:
        os.close(self.fd)
        self.fd = None

    def drain(self) -> None:
        """Read what is readable now into the streams."""
        if self.fd is None:
            self._open()
        while self.fd is not None:
            try:
                data = os.read(self.fd, CHUNK)
            except BlockingIOError:
                break
            except OSError as e:
                if e.errno != errno.EIO:
                    raise
                data = b""  # EIO: the emulator closed its end (unplugged)
            if not data:
                self._hang_up()
                break
            for stream in (self.stream, *self._taps):
                stream.feed(data)

    def wait(self, seconds: float) -> None:
        """Until bytes are readable or *seconds* of wall time have passed."""
        if self.fd is None:
            select.select([], [], [], seconds)  # nothing to wait on until the link is back
        else:
            select.select([self.fd], [], [], seconds)

    def close(self) -> None:
        if self.fd is not None:
            self._hang_up()

    # -- time ------------------------------------------------------------------------------
    @property
    def virtual(self) -> bool:
        return self.lab.info["speed"] != "realtime"

    def now(self) -> float:
        """Device time (virtual time) or wall time, in seconds."""
        return self.lab.status()["virtual_s"] if self.virtual else time.monotonic()

    def _until(self, seconds: float, done) -> tuple[object, float, float]:
        """Feed the stream until ``done()`` gives a result or *seconds* (device or wall time)
        pass; (result or None, device seconds waited, wall seconds waited)."""
        t0, w0 = self.now(), time.monotonic()
        while True:
            self.drain()
            found = done()
            if found is not None:
                return found, self.now() - t0, time.monotonic() - w0
            now = self.now()
            if now - t0 >= seconds:  # what was written before the clock read is readable
                self.drain()
                return done(), now - t0, time.monotonic() - w0
            if not self.lab.running():
                self.drain()
                found = done()
                if found is None:
                    raise ExpectError(self.message(f"the lab ended while waiting on port "
                                                    f"{self.port!r}", now - t0,
                                                    time.monotonic() - w0))
                return found, now - t0, time.monotonic() - w0
            self.wait(CLOCK_S if self.virtual else seconds - (now - t0))

    def message(self, head: str, device_s: float, wall_s: float) -> str:
        clock = (f"{device_s:.3f} s device time ({wall_s:.3f} s wall, lab at speed "
                 f"{self.lab.info['speed']})" if self.virtual else f"{wall_s:.3f} s wall time "
                 "(real-time lab)")
        return (f"{head} after {clock}; {self.stream.bytes} bytes read on port {self.port!r} "
                f"in all; last frames decoded:\n{self.stream.last_frames()}")

    # -- the expectations ------------------------------------------------------------------
    def expect(self, match, timeout: float):
        m = Match(match)
        found, dev, wall = self._until(timeout, lambda: self.stream.take(m))
        if found is None:
            raise ExpectTimeout(self.message(f"lab.expect: nothing matching {m} on port {self.port!r} within "
                                              f"{timeout:g} s", dev, wall))
        return found

    def expect_none(self, match, within: float) -> None:
        m = Match(match)
        self.drain()
        self.stream.skip()  # what came before the call is not in the window
        found, dev, wall = self._until(within, lambda: self.stream.take(m))
        if found is not None:
            what = found.group(0) if hasattr(found, "group") else found
            raise Unexpected(self.message(f"lab.expect_none: {m} came on port {self.port!r} "
                                           f"within the {within:g} s window: {what!r}",
                                           dev, wall))

    def idle(self, seconds: float) -> None:
        self.drain()
        self.stream.skip()
        start = self.stream.bytes
        seen = lambda: (self.stream.bytes - start) or None  # noqa: E731 - bytes since the call
        came, dev, wall = self._until(seconds, seen)
        if came is not None:
            raise Unexpected(self.message(f"lab.idle: port {self.port!r} was not idle for "
                                           f"{seconds:g} s: {came} bytes came", dev, wall))


class Checks:
    """``navtwin emulate --expect/--fail-on/--timeout``: on each port, its expects in order
    and its fail-ons all along (each on a tap of its own, so they see every frame), one thread
    per port. :attr:`failure` is the first failure's message; :attr:`passed` is set when every
    expect was seen (the run can stop) or, with fail-ons only, when *timeout* passed clean."""

    def __init__(self, lab, scenario, expects: list[tuple[str, Match]],
                 fail_ons: list[tuple[str, Match]], timeout: float | None) -> None:
        names = list(dict.fromkeys(p for p, _ in expects + fail_ons))
        self.watches = {p: PortWatch(lab, p, scenario) for p in names}
        self.expects = {p: [m for q, m in expects if q == p] for p in names}
        self.fail_ons = {p: [(m, self.watches[p].tap()) for q, m in fail_ons if q == p]
                         for p in names}
        self.lab, self.timeout = lab, timeout
        self._remaining = len(expects)
        self._any_expects = bool(expects)
        self._lock = threading.Lock()
        self.failure: str | None = None
        self.passed = False

    def run(self) -> None:
        """Until every port's checks are decided or one fails (then the others stop too)."""
        threads = [threading.Thread(target=self._port, args=(p,), daemon=True)
                   for p in self.watches]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        self.passed = self.failure is None
        for w in self.watches.values():
            w.close()

    def _port(self, port: str) -> None:
        watch, pending = self.watches[port], list(self.expects[port])
        t0, w0 = watch.now(), time.monotonic()
        while self.failure is None:
            watch.drain()
            for m, tap in self.fail_ons[port]:
                found = tap.take(m)
                if found is not None:
                    what = found.group(0) if hasattr(found, "group") else found
                    return self._fail(watch, f"--fail-on: {m} came on port {port!r}: {what!r}",
                                      t0, w0)
            while pending and watch.stream.take(pending[0]) is not None:
                pending.pop(0)
                with self._lock:
                    self._remaining -= 1
            if self._any_expects and self._remaining == 0:
                return  # every expect seen: the fail-ons are done watching too
            if not pending and not self.fail_ons[port]:
                return
            if self.timeout is not None and watch.now() - t0 >= self.timeout:
                if pending:
                    self._fail(watch, f"--expect: nothing matching {pending[0]} on port "
                                      f"{port!r} within {self.timeout:g} s", t0, w0)
                return
            if not self.lab.running():
                if pending:
                    self._fail(watch, f"--expect: the run ended before {pending[0]} came on "
                                      f"port {port!r}", t0, w0)
                return
            watch.wait(CLOCK_S)

    def _fail(self, watch: PortWatch, head: str, t0: float, w0: float) -> None:
        if self.failure is None:
            self.failure = watch.message(head, watch.now() - t0, time.monotonic() - w0)
