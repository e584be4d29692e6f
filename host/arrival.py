"""When a device's chunk reaches the lab computer, for runs that have device times only.

The emulator times each chunk by when its first byte leaves the device's UART. The lab
computer has it when its last byte has arrived: ``t_device_ns + wire_ns(size, baud)`` (8N1,
:func:`navtwin.protocols.serial.wire_ns`). Across ports the chunks are taken in that order, ties in
the order ``xbee``, ``sins``, ``nanoloc`` (then each port's own order), and the stamps are made
strictly increasing. ``navtwin replay`` of an emulator recording and the in-memory run
(:func:`navtwin.lab.run.run_in_memory`) both stamp with :func:`arrivals`, so they give the same lines.
"""
from __future__ import annotations

import heapq
from collections.abc import Iterable, Iterator, Mapping

import numpy as np

from navtwin.protocols.serial import wire_ns

from navtwin.protocols.ports import host_inputs


def arrivals(streams: Mapping[str, Iterable[tuple[bytes, int]]],
             bauds: Mapping[str, int]) -> Iterator[tuple[str, bytes, int]]:
    """``(port, bytes, arrival ns)`` in processing order, from each port's ``(bytes,
    t_device_ns)`` in device order (ports the host reads) and its rate in *bauds*."""
    order = {p: i for i, p in enumerate(host_inputs())}

    def timed(port: str):
        baud = bauds[port]
        for k, (data, t_ns) in enumerate(streams[port]):
            yield t_ns + wire_ns(len(data), baud), order[port], k, port, data

    last = -1
    for t, _, _, port, data in heapq.merge(*(timed(p) for p in streams)):
        last = max(t, last + 1)
        yield port, data, last


def split(ports: Mapping[str, tuple[bytes, np.ndarray, np.ndarray]]) -> dict[str, list[tuple[bytes, int]]]:
    """Each port's ``(data, sizes, start_ns)`` arrays (its chunks joined, one size and device
    time a chunk) as the ``(bytes, t_device_ns)`` chunks :func:`arrivals` takes."""
    out = {}
    for port, (data, sizes, start_ns) in ports.items():
        ends = np.cumsum(sizes).tolist()
        out[port] = [(data[a:b], t) for a, b, t in zip([0, *ends], ends, start_ns.tolist())]
    return out
