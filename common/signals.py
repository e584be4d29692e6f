"""A signal handler that stops a long-running command, safe when signals come close together.

Python runs a signal's handler in the main thread between two bytecodes, so a second signal
can run the handler again inside the first. ``threading.Event.set`` takes the event's lock:
a handler that calls it, run again while the first holds that lock, waits for it forever
(seen: a worker whose parent was killed, ``PR_SET_PDEATHSIG``'s SIGTERM and a second signal
while it waited for its start line). The handler here sets the event once: a run inside the
first, once the first has begun, returns at once.
"""
from __future__ import annotations

import threading


def stopper(stop: threading.Event):
    """A handler for ``signal.signal`` that sets *stop*, once."""
    begun = []

    def handler(*_) -> None:
        if begun:  # this runs inside the first run, which sets it
            return
        begun.append(True)
        stop.set()

    return handler
