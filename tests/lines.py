"""A subprocess's output lines as they come, and waiting for a JSON line with a deadline."""
from __future__ import annotations

import json
import re
import threading
import time


class Lines:
    """The lines of *stream* (a text pipe), collected by a thread; ``lines`` grows as they
    come (a process's stdout or stderr)."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self.ended = False
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._pump, args=(stream,), daemon=True)
        self._thread.start()

    def _pump(self, stream) -> None:
        for line in stream:
            with self._cond:
                self.lines.append(line)
                self._cond.notify_all()
        with self._cond:
            self.ended = True
            self._cond.notify_all()

    def text(self) -> str:
        return "".join(self.lines)

    def join(self, timeout: float = 5.0) -> None:
        """Wait until the stream has ended (the process has exited and closed it)."""
        self._thread.join(timeout)

    def wait(self, pred, what: str, timeout: float) -> dict:
        """The first JSON line for which *pred* is true; AssertionError at the end of the
        stream or after *timeout* s."""
        def parsed(line: str):
            try:
                obj = json.loads(line)
            except json.JSONDecodeError:
                return None
            return obj if pred(obj) else None

        return self._first(parsed, what, timeout)

    def search(self, pattern: str, what: str, timeout: float) -> re.Match:
        """The match of the regex *pattern* in the first line that has one (as :meth:`wait`)."""
        return self._first(re.compile(pattern).search, what, timeout)

    def _first(self, found, what: str, timeout: float):
        deadline = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                while seen < len(self.lines):
                    seen += 1
                    if (hit := found(self.lines[seen - 1])) is not None:
                        return hit
                if self.ended:
                    raise AssertionError(f"{what}: the stream ended first")
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {what} within {timeout} s")
                self._cond.wait(left)
