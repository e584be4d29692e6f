"""When a device's chunk reaches the lab computer, for runs that have device times only.

The emulator times each chunk by when its first byte leaves the device's UART. The lab
computer has it when its last byte has arrived: ``t_device_ns + wire_ns(size, baud)`` (8N1,
:func:`navtwin.protocols.serial.wire_ns`). Across ports the chunks are taken in that order, ties in
the order ``xbee``, ``sins``, ``nanoloc`` (then each port's own order), and the stamps are made
strictly increasing. ``navtwin replay`` of an emulator recording and the in-memory run
(:func:`navtwin.lab.run.run_in_memory`) both stamp with :func:`arrivals`, so they give the same lines.
:func:`processing_order` is the same rule on whole arrays (the batch engine's bulk path,
host.batch.chunks).
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


def processing_order(ports: Mapping[str, tuple[bytes, np.ndarray, np.ndarray]],
                     bauds: Mapping[str, int]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """:func:`arrivals` on whole arrays: for each port's ``(data, sizes, start_ns)`` (as
    :func:`split` takes them), each chunk's place in the processing order, and the stamps
    (ns) in that order. The merge is a sort by (arrival, port order, index) and the strictly
    increasing stamps ``cummax(t_i - i) + i``, in integers. ValueError where a port's own
    chunks arrive out of their order (the merge of :func:`arrivals` then is no sort)."""
    rank = {p: i for i, p in enumerate(host_inputs())}
    names = sorted(ports, key=rank.__getitem__)
    times = []
    for p in names:
        _, sizes, start = ports[p]
        times.append(start + wire_ns(sizes, bauds[p]))
        if (np.diff(times[-1]) < 0).any():
            raise ValueError(f"{p}'s chunks arrive out of their order")
    t = np.concatenate(times) if times else np.zeros(0, np.int64)
    port_rank = np.concatenate([np.full(len(x), rank[p]) for p, x in zip(names, times)] or [[]])
    index = np.concatenate([np.arange(len(x)) for x in times] or [[]])
    order = np.lexsort((index, port_rank, t))
    i = np.arange(len(t))
    stamp = np.maximum.accumulate(t[order] - i) + i
    position = np.empty(len(t), np.int64)
    position[order] = i
    return dict(zip(names, np.split(position, np.cumsum([len(x) for x in times])[:-1]))), stamp
