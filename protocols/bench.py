"""The decoders' benchmarks, with peers measured in the same run (``navtwin bench decode``).

:func:`decode_benchmarks` is this package's set of ``navtwin bench`` (the registry is
:mod:`navtwin.cli.bench`): library functions that return figures, over protocols alone.
This module also holds the adapters that run the two peer XBee libraries' own read paths over
bytes in memory (digi-xbee 1.5.0 and python-xbee 2.3.2 are test-extra dependencies, imported
only here).
"""
from __future__ import annotations

import statistics
import time

from . import nanoloc, sins, xbee
from .stream import XBeeDecoder, XBeeSinsChain, nanoloc_decoder, sins_decoder

ROUTER64 = 0x0013A20040A1B2D4
ROUTER16 = 0x3C41


# -- peers: their own stream read paths, over bytes in memory ------------------------------

def digi_frames(stream: bytes, escaped: bool) -> list:
    """digi-xbee's PacketListener path: ``XBeeSerialPort.wait_for_frame`` then
    ``factory.build_frame``, reading from memory instead of a serial port."""
    from digi.xbee.exception import InvalidPacketException, TimeoutException
    from digi.xbee.models.mode import OperatingMode
    from digi.xbee.packets.factory import build_frame
    from digi.xbee.serial import XBeeSerialPort

    class MemoryPort:
        wait_for_frame = XBeeSerialPort.wait_for_frame
        _XBeeSerialPort__read_next_byte = XBeeSerialPort._XBeeSerialPort__read_next_byte

        def __init__(self, data: bytes) -> None:
            self._data, self._pos, self._is_reading = data, 0, True

        def read_byte(self) -> int:  # XBeeSerialPort.read_byte minus the serial call
            if self._pos >= len(self._data):
                raise TimeoutException()
            self._pos += 1
            return self._data[self._pos - 1]

    mode = OperatingMode.ESCAPED_API_MODE if escaped else OperatingMode.API_MODE
    port = MemoryPort(stream)
    packets = []
    while port._pos < len(stream):
        raw = port.wait_for_frame(mode)
        if raw is None:
            break
        try:
            packets.append(build_frame(raw, mode))
        except InvalidPacketException:
            continue
    return packets


def pyxbee_frames(stream: bytes, escaped: bool) -> list[dict]:
    """python-xbee's ``_wait_for_frame`` loop (skip to 7E, ``APIFrame.fill`` until complete,
    ``parse``) and ``_split_response``, reading from memory instead of a serial port."""
    from xbee import ZigBee  # the threaded class; no thread starts without a callback
    from xbee.frame import APIFrame

    zb = ZigBee(None, escaped=escaped)
    out = []
    pos, n = 0, len(stream)
    while pos < n:
        byte = stream[pos:pos + 1]
        pos += 1
        if byte != APIFrame.START_BYTE:
            continue
        frame = APIFrame(escaped=escaped)
        frame.fill(byte)
        while frame.remaining_bytes() > 0 and pos < n:
            frame.fill(stream[pos:pos + 1])
            pos += 1
        try:
            frame.parse()
            out.append(zb._split_response(frame.data))
        except (ValueError, KeyError):
            continue
    return out


# -- workloads ------------------------------------------------------------------------------

def sins_stream(n: int, seed: int = 1) -> bytes:
    import numpy as np

    words = np.random.default_rng(seed).integers(0, 65536, size=(n, 11))
    return b"".join(sins.build_sample(k, row.tolist()) for k, row in enumerate(words))


def xbee_sins_stream(n: int, escaped: bool = True, packet: int = 30, seed: int = 1) -> bytes:
    """The coordinator's output for *n* SINS frames: 0x90 packets of *packet* bytes (one SINS
    frame per packet, as RO = 3 character times gives at 100 Hz)."""
    data = sins_stream(n, seed)
    return b"".join(xbee.build(0x90, escaped=escaped, src64=ROUTER64, src16=ROUTER16, options=1,
                               data=data[i:i + packet]) for i in range(0, len(data), packet))


def nanoloc_stream(n: int) -> bytes:
    return b"".join(nanoloc.build_report(seq=k, t_us=25_000 * k, anchor=1 + k % 4, tag=0x10,
                                         status=0x0F, rssi=-60, tau=[100_033_356, 100_000_000,
                                                                      100_033_356, 100_000_000])
                    for k in range(n))


def _time(fn, stream: bytes, repeat: int) -> float:
    """Median CPU seconds (``time.process_time``) of *repeat* runs of ``fn(stream)``: CPU time,
    not wall time, so a loaded machine's waits do not favour whichever run was shorter."""
    runs = []
    for _ in range(repeat):
        t = time.process_time()
        fn(stream)
        runs.append(time.process_time() - t)
    return statistics.median(runs)


def _time_pair(ours, peer, stream: bytes, repeat: int) -> tuple[float, float]:
    """Median CPU seconds of *ours* and *peer* on *stream*, their runs alternated so a change
    of load in the middle of the benchmark weighs on both alike."""
    a, b = [], []
    for _ in range(repeat):
        a.append(_time(ours, stream, 1))
        b.append(_time(peer, stream, 1))
    return statistics.median(a), statistics.median(b)


def _decode_all(make):
    def run(stream):
        dec = make()
        for k in range(0, len(stream), 4096):
            dec.feed(stream[k:k + 4096])
        dec.flush()
    return run


def bench_decode(quick: bool = False) -> dict:
    """MB/s and frames/s of each decoder, and of the peers on the same escaped 0x90 stream, in
    CPU time (medians); each ratio compares the xbee-sins chain with a peer in this run."""
    n = 2000 if quick else 20000
    repeat = 3 if quick else 7
    cases = {
        "sins": (sins_stream(n), sins_decoder, n),
        "nanoloc": (nanoloc_stream(n), nanoloc_decoder, n),
        "xbee-api1": (xbee_sins_stream(n, escaped=False), lambda: XBeeDecoder(False), n),
        "xbee-api2": (xbee_sins_stream(n), lambda: XBeeDecoder(True), n),
        "xbee-sins": (xbee_sins_stream(n), XBeeSinsChain, n),
    }
    results = {}
    for name, (stream, make, frames) in cases.items():
        s = _time(_decode_all(make), stream, repeat)
        results[name] = {"MB/s": round(len(stream) / s / 1e6, 3), "frames/s": round(frames / s),
                         "bytes": len(stream), "median_s": round(s, 5)}
    escaped = cases["xbee-api2"][0]
    chain = _decode_all(XBeeSinsChain)
    for peer, fn in (("digi-xbee", digi_frames), ("python-xbee", pyxbee_frames)):
        try:
            ours, s = _time_pair(chain, lambda b, fn=fn: fn(b, True), escaped, repeat)
        except ImportError as e:
            results[peer] = {"skipped": str(e)}
            continue
        results[peer] = {"MB/s": round(len(escaped) / s / 1e6, 3), "frames/s": round(n / s),
                         "bytes": len(escaped), "median_s": round(s, 5)}
        # the CPU-time ratio of the host's chain (API 2 -> 0x90 payloads -> SINS frames) to the
        # peer's parser on the same bytes, both timed alternately in this run
        results[f"xbee-sins vs {peer}"] = round(s / ours, 1)
    return results


def decode_benchmarks() -> dict:
    return {"decode": bench_decode}
