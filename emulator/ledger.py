"""The fault ledger of a run: one entry per injection, whatever the fault acts on.

An entry is a flat JSON object::

    {"kind": "byte_drop", "fault": 2, "port": "sins", "direction": "to_host",
     "t_ns": 1520000000, "start": 4410, "end": 4410, "removed": 1}

``kind`` and ``fault`` (its place in the scenario's ``[[faults]]``, from 0) name the fault;
``port`` and ``direction`` the stream it touched (None for a fault on no port); ``t_ns`` the
device time of the injection; ``[start, end)`` the bytes it touched in that stream as
delivered (for ``to_host``: offsets in the recorded ``<port>.bin``; for ``to_device``: in
the bytes the device received), ``start == end`` where bytes were removed (``removed``
says how many). Other keys are the kind's details (a flipped ``mask``, a ``held_ns``, ...).

Line faults add entries through their line (emulator.uart); a device fault marks the items
it changed (emulator.uart.Marked: an anchor's timed-out or biased report, the board's first
frame after a reset, the coordinator's power-up frame), and the line adds an entry over the
bytes each became. A line adds an entry once the bytes it names are delivered, so a
stopped run's ledger names only bytes it recorded. The Emulation writes each entry into
its recording's ``faults.jsonl`` (protocols.recording) and keeps per-kind totals for its
summary.
"""
from __future__ import annotations

from typing import Callable


class Ledger:
    """Entries as they are added: to *write* (a recording), and kept in :attr:`entries`
    when *keep* (in-memory runs and tests; a recorded run has them in its file)."""

    def __init__(self, write: Callable[[dict], None] | None = None, keep: bool = True,
                 faults: tuple = ()) -> None:
        self._write = write
        self._index = {id(f): i for i, f in enumerate(faults)}  # the scenario's [[faults]]
        self.entries: list[dict] | None = [] if keep else None
        self._totals: dict[str, dict] = {}

    def add(self, *, kind: str, fault: int | None, port: str | None, t_ns: int,
            start: int | None = None, end: int | None = None, direction: str | None = None,
            **detail) -> None:
        entry = {"kind": kind, "fault": fault, "port": port, "direction": direction,
                 "t_ns": int(t_ns), "start": start, "end": end, **detail}
        total = self._totals.setdefault(kind, {"injections": 0, "bytes": 0})
        total["injections"] += 1
        total["bytes"] += touched(entry)
        if self.entries is not None:
            self.entries.append(entry)
        if self._write is not None:
            self._write(entry)

    def index(self, fault) -> int | None:
        """*fault*'s place in the scenario's [[faults]]; None for a live one (or an int as is)."""
        return fault if fault is None or isinstance(fault, int) else self._index.get(id(fault))

    def totals(self) -> dict[str, dict]:
        """Per kind: ``injections`` (entries) and ``bytes`` (touched: see :func:`touched`)."""
        return {k: dict(v) for k, v in self._totals.items()}


def touched(entry: dict) -> int:
    """Bytes an entry touched: its range plus the bytes it removed."""
    start, end = entry.get("start"), entry.get("end")
    return (end - start if start is not None and end is not None else 0) + entry.get("removed", 0)
