"""How a paced run waits for its deadlines: the timing modes, and how late its writes were.

A paced run (``--speed realtime`` or a FACTOR) writes each chunk at an absolute deadline on
CLOCK_MONOTONIC. Its loop sleeps in ``select`` (so a client's write or a control request wakes
it) until the deadline, or, where nothing better exists (``spin``), until ``spin_ns`` before it
and spins the rest. How late the sleep ends is what
the kernel allows the thread:

- ``timer slack``: the kernel may delay a sleeping thread's wake-up by its slack (50 us by
  default) to batch timers; ``prctl(PR_SET_TIMERSLACK, 1)`` asks for 1 ns, so ``select``
  ends near the deadline and the spin can be shorter;
- ``SCHED_FIFO``: a thread of a real-time policy runs as soon as it is woken, before every
  ordinary thread; under load the ordinary thread waits for its turn, often milliseconds.

Modes, best first (:data:`MODES`): ``fifo`` (SCHED_FIFO at :data:`PRIORITY`, plus what
``slack`` does), ``slack`` (1 ns timer slack), each sleeping to the deadline, and ``spin``
(neither: the default slack, and a spin to cover it). ``auto`` takes the first the process is permitted: each mode's
:meth:`Mode.check` tries its system calls and undoes them, so a mode refused
(PermissionError, or no such call on this system) falls to the next. A mode is applied to the
thread that runs the loop, for the run only (:meth:`Mode.applied`), and undone after:
the process's other threads (the control socket's, an ``--expect`` watcher, RFC 2217
servers) and its children (the world's maker process, emulator.maker, forked before the
mode is applied) stay ordinary (``SCHED_RESET_ON_FORK``).

Safety. A SCHED_FIFO thread that never sleeps starves every ordinary thread on its core; the
loop sleeps to each deadline and then writes, so it sleeps in every period; the kernel's real-time throttling (``kernel.sched_rt_runtime_us``, 95 % by default)
bounds the rest. Memory is not locked (``mlockall``): it is process-wide and cannot be undone
for a run alone, and the loop's memory is made before the clock starts (``gc.freeze``).

Lateness. :class:`Lateness` counts, per port, how late each chunk was written against its
schedule (wall time minus the chunk's end in device time, divided by the speed), in fixed
log-spaced bins (:data:`BINS`): a run's timing fidelity at a glance, in its summary and its
recording's meta.
"""
from __future__ import annotations

import bisect
import contextlib
import ctypes
import errno
import functools
import os

PRIORITY = 10  # SCHED_FIFO priority: above ordinary threads, below the kernel's own (50)
PR_SET_PDEATHSIG, PR_SET_TIMERSLACK, PR_GET_TIMERSLACK = 1, 29, 30  # <linux/prctl.h>
SLACK_NS = 1  # the least timer slack the kernel takes (0 would mean "the default")


class TimingError(ValueError):
    """A timing mode this process may not use; the message is one line with the fix."""


class Mode:
    """Spin the last ``spin_ns`` before a deadline; ask the kernel for nothing."""

    name = "spin"
    #: after its writes the loop yields the CPU, so a client they woke runs first
    yields = True
    #: busy-wait this long before a deadline: ``select``'s wake-up with the default 50 us
    #: timer slack, plus the loop's own work (overshoot p50 ~0.1 ms here)
    spin_ns = 250_000

    def check(self) -> None:
        """Raise OSError if this process may not use the mode (the probe leaves no trace)."""

    @contextlib.contextmanager
    def applied(self):
        """The mode on the calling thread while the block runs, undone after."""
        yield


class Slack(Mode):
    """1 ns timer slack, so ``select`` wakes at the deadline asked and the spin is short."""

    name = "slack"
    #: none: the sleep ends within ~40 us of the deadline (p50) with 1 ns slack, and a spin
    #: at every deadline cost a quarter of the loop's CPU at 25 vehicles (docs/emulator.md)
    spin_ns = 0

    def check(self) -> None:
        with self.applied():
            pass

    @contextlib.contextmanager
    def applied(self):
        old = _prctl(PR_GET_TIMERSLACK)
        _prctl(PR_SET_TIMERSLACK, SLACK_NS)
        try:
            yield
        finally:
            _prctl(PR_SET_TIMERSLACK, old)


class Fifo(Slack):
    """SCHED_FIFO at :data:`PRIORITY` (children and new threads reset to ordinary), plus
    :class:`Slack`'s 1 ns timer slack."""

    name = "fifo"
    yields = False  # a real-time thread's yield gives way to no ordinary thread

    @contextlib.contextmanager
    def applied(self):
        # the slack first: Linux 6.7+ gives a real-time thread no slack at all (and ignores
        # PR_SET_TIMERSLACK while it is one), so the ordinary thread's slack is saved here
        with super().applied():
            policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK,
                                  os.sched_param(PRIORITY))
            try:
                yield
            finally:
                os.sched_setscheduler(0, policy, param)


#: mode name -> its class, best first: the order ``auto`` tries them in
MODES: dict[str, type[Mode]] = {"fifo": Fifo, "slack": Slack, "spin": Mode}
NAMES = ("auto", *MODES)
FIXES = {"fifo": "run as root, give the program CAP_SYS_NICE or raise RLIMIT_RTPRIO "
                 "(ulimit -r 10)",
         "slack": "use Linux"}


def choose(name: str = "auto") -> Mode:
    """The mode *name*, or for ``auto`` the best the process may use; TimingError if a mode
    named is not permitted."""
    if name == "auto":
        for cls in MODES.values():
            with contextlib.suppress(OSError):
                return _checked(cls)
    if name not in MODES:
        raise TimingError(f"timing: {name!r} is not one of {', '.join(NAMES)}; use one of them")
    try:
        return _checked(MODES[name])
    except OSError as e:
        raise TimingError(f"timing: {name} is not permitted here ({e.strerror or e}); "
                          f"{FIXES[name]}, or choose auto") from None


def _checked(cls: type[Mode]) -> Mode:
    mode = cls()
    mode.check()
    return mode


def die_with_parent(parent: int, sig: int) -> bool:
    """Ask the kernel for *sig* when this process's parent dies (``PR_SET_PDEATHSIG``: a
    parent killed outright cannot stop its children); False when *parent* already died."""
    _prctl(PR_SET_PDEATHSIG, sig)
    return os.getppid() == parent


def _prctl(option: int, value: int = 0) -> int:
    """prctl(2) for the timer slack: the value got (GET) or 0; OSError where there is none."""
    prctl = getattr(_libc(), "prctl", None)
    if prctl is None:
        raise OSError(errno.ENOSYS, "no prctl on this system")
    result = prctl(option, ctypes.c_ulong(value), ctypes.c_ulong(0), ctypes.c_ulong(0),
                   ctypes.c_ulong(0))
    if result < 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))
    return result


@functools.cache
def _libc():
    return ctypes.CDLL(None, use_errno=True)


#: upper edges of the lateness bins (ns); a last bin holds the rest
EDGES_NS = (10_000, 30_000, 100_000, 300_000, 1_000_000, 3_000_000, 10_000_000)


def _label(ns: int) -> str:
    return f"{ns // 1000}us" if ns < 1_000_000 else f"{ns // 1_000_000}ms"


#: the bins' names, in order: "<10us" ... "<10ms", ">=10ms"
BINS = (*(f"<{_label(e)}" for e in EDGES_NS), f">={_label(EDGES_NS[-1])}")


class Lateness:
    """Per port, how many chunks were written how late (:data:`BINS`)."""

    def __init__(self, ports) -> None:
        self.counts = {name: [0] * len(BINS) for name in ports}

    def add(self, port: str, late_ns: int) -> None:
        self.counts[port][bisect.bisect_right(EDGES_NS, late_ns)] += 1

    def histograms(self) -> dict[str, dict[str, int]]:
        return {name: dict(zip(BINS, c)) for name, c in self.counts.items()}
