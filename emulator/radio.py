"""The XBee pair's RF side: the router's packetisation and the 2.4 GHz link.

Router (transparent mode, AP = 0). Bytes from the board arrive on its UART one character
time apart within a frame. The router sends its buffer as one RF packet when RO character
times pass with no new byte (the gap to the next byte is longer than RO x 10 bits / baud),
or at once when NP bytes are buffered. So at 115200 baud with RO = 3 and NP = 84 every
30-byte SINS frame becomes one packet, sent 3 character times after its last byte.

Link (IEEE 802.15.4 at 250 kbit/s, unicast with MAC acknowledgement). The router sends
one packet at a time. Each attempt takes a random CSMA backoff (uniform in [0, jitter_ms]),
the frame's airtime ((payload + 33 bytes of PHY, MAC, NWK and APS overhead + FCS) x 32 us)
and then the ACK (544 us) or, when the attempt is lost (probability per_attempt_loss, or
always inside a ``link_loss`` fault), the ACK wait (retry_ms) before the next attempt. After
max_retries lost retries the packet is gone. A delivered packet reaches the coordinator's
radio latency_ms after the end of its successful airtime. Sources: Digi ZB manual (NP, RO,
retries), IEEE 802.15.4-2006 (250 kbit/s, 54-symbol ACK wait), xbee-api-facts.md section 5.

Air. The 33 bytes of overhead are the headers of the frame each attempt puts on the air
(protocols.ieee802154, protocols.zigbee, sized there); :class:`Sender` builds those frames
from the attempts the link drew (:class:`Attempts`: each one's first bit on the air, lost
or not), and the receiver's MAC ACK one turnaround after each received one. The air adds
no draw: the frames are a view of the same attempts.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from navtwin.protocols import ieee802154, zigbee
from navtwin.protocols.ieee802154 import ACK_NS, BYTE_NS, TURNAROUND_NS

from .clock import serial_queue
from .events import rows

RF_OVERHEAD_BYTES = zigbee.OVERHEAD_BYTES  # PHY 6 + MAC 9 + NWK 8 + APS 8 + FCS 2
OPT_ACKNOWLEDGED = 0x01  # 0x90 receive option: unicast, acknowledged


class Packets(NamedTuple):
    ready_ns: np.ndarray  # when the router closed each packet
    payloads: list[bytes]


class Router:
    """Packetiser of the router's UART input (bytes with their arrival times)."""

    def __init__(self, np_bytes: int, ro_chars: int, char_ns: float) -> None:
        self.np = np_bytes
        self.ro_ns = ro_chars * char_ns
        self._data = b""  # an open packet carried to the next block
        self._times = np.empty(0, dtype=np.int64)

    def packetise(self, data: bytes, times: np.ndarray, next_byte_ns: int | None) -> Packets:
        """Packets closed by the bytes *data* that arrive at *times*; *next_byte_ns* is the
        arrival of the byte after them (None: no more bytes, flush)."""
        data = self._data + data
        a = np.concatenate((self._times, times))
        if not len(a):
            return Packets(np.empty(0, dtype=np.int64), [])
        gap_after = np.diff(a, append=np.inf if next_byte_ns is None else next_byte_ns)
        ends = np.flatnonzero(gap_after > self.ro_ns) + 1  # exclusive ends of silent-gap runs
        # a closed run goes as NP chunks, the last one short; the open run after the last
        # end sends its full NP chunks now, and the rest waits for more bytes
        starts = np.concatenate(([0], ends))[:-1]
        chunks = -(-(ends - starts) // self.np)
        first = np.cumsum(chunks) - chunks  # each run's first chunk
        lo = np.repeat(starts, chunks) + self.np * (np.arange(int(chunks.sum())) - np.repeat(first, chunks))
        hi = np.minimum(lo + self.np, np.repeat(ends, chunks))
        ready = a[hi - 1] + np.where(hi - lo == self.np, 0, round(self.ro_ns))
        start = int(ends[-1]) if len(ends) else 0
        full = start + self.np * np.arange(1, (len(a) - start) // self.np + 1)  # open run's ends
        lo, hi = np.concatenate((lo, full - self.np)).tolist(), np.concatenate((hi, full)).tolist()
        rest = int(full[-1]) if len(full) else start  # the bytes that wait
        self._data, self._times = data[rest:], a[rest:]
        return Packets(np.concatenate((ready, a[full - 1])).astype(np.int64),
                       [data[i:j] for i, j in zip(lo, hi)])


@dataclass(slots=True)
class AttemptEffects:
    """What link faults (emulator.faults, ACTS_ON "link") change: ``lost`` (packets x
    attempts, bool), changed in place; ``u`` the uniform draw that decided each attempt."""

    lost: np.ndarray
    u: np.ndarray


class Attempts(NamedTuple):
    """The attempts of n packets (``Link.max_retries + 1`` columns; packet i makes
    ``count[i]`` of them, the rest are never sent)."""

    delivered: np.ndarray  # (n,) bool
    retries: np.ndarray  # (n,) retries before delivery (max_retries when lost)
    offset: np.ndarray  # (n,) first attempt's start to delivery at the coordinator's radio
    service: np.ndarray  # (n,) how long the packet holds the radio
    on_air_ns: np.ndarray  # (n, tries) each attempt's first bit (preamble) on the air
    lost: np.ndarray  # (n, tries) bool: the attempt was not received (not ACKed)
    air_ns: np.ndarray  # (n,) one attempt's PPDU duration
    start_ns: np.ndarray | None = None  # (n,) transmit's: when each packet took the radio

    @property
    def count(self) -> np.ndarray:
        """Attempts made per packet: up to the delivering one, or every one when lost."""
        return self.retries + 1


class Link:
    """One direction of the RF link with its own random stream."""

    def __init__(self, spec, faults, rng: np.random.Generator) -> None:
        self.spec = spec
        self.faults = tuple(faults)  # emulator.faults acting on the link
        self.rng = rng
        self.busy_until = 0
        self._hits: list = []  # (fault, packets in its episode) of the last packets sent
        self._lost: dict | None = None  # a fault's packets lost since the last delivered one

    def _attempts(self, start_ns: np.ndarray, sizes: np.ndarray) -> "Attempts":
        """Every attempt of packets whose first attempt starts at *start_ns*; offsets are ns
        from that start."""
        s = self.spec
        n, tries = len(start_ns), s.max_retries + 1
        u = self.rng.random((n, 2 * tries))
        effect = AttemptEffects(u[:, :tries] < s.per_attempt_loss, u[:, :tries])
        hits = []
        for fault in self.faults:
            on = fault.active(start_ns)
            fault.act(effect, on)
            hits.append((fault, on))
        self._hits = hits
        lost = effect.lost
        backoff = np.rint(u[:, tries:] * s.jitter_ms * 1e6).astype(np.int64)
        air = ((sizes + RF_OVERHEAD_BYTES) * BYTE_NS)[:, None]
        attempt = backoff + air + np.where(lost, round(s.retry_ms * 1e6), ACK_NS)
        delivered = ~lost.all(axis=1)
        retries = np.where(delivered, np.argmin(lost, axis=1), s.max_retries)
        on_air = np.cumsum(attempt, axis=1) - attempt + backoff  # each attempt's first bit
        rows = np.arange(n)
        offset = on_air[rows, retries] + air[:, 0] + round(s.latency_ms * 1e6)
        service = np.where(delivered, on_air[rows, retries] - backoff[rows, retries]
                           + attempt[rows, retries], attempt.sum(axis=1))
        return Attempts(delivered, retries, offset, service, on_air, lost, air[:, 0])

    def transmit(self, ready_ns: np.ndarray, sizes: np.ndarray):
        """Send packets in order, one at a time: (arrival_ns, delivered) per packet, the
        ledger marks by packet index (the first packet delivered after packets a link fault
        lost says which fault, when and how many), and the attempts (:class:`Attempts`, their
        ``on_air_ns`` in true time)."""
        sizes = np.asarray(sizes, dtype=np.int64)
        start = np.asarray(ready_ns, dtype=np.int64)
        attempts = self._attempts(start, sizes)
        delivered, offset, service = attempts.delivered, attempts.offset, attempts.service
        marks: dict[int, tuple] = {}
        if self._hits or self._lost:
            for i in range(len(start)):
                if not delivered[i]:
                    cause = next((f for f, on in self._hits if on[i]), None)
                    if cause is not None:
                        lost = self._lost or {"kind": cause.KIND, "fault": cause,
                                              "t_ns": int(start[i]), "lost": 0}
                        lost["lost"] += 1
                        self._lost = lost
                elif self._lost is not None:
                    marks[i], self._lost = (self._lost,), None
        start, end = serial_queue(start, service, self.busy_until)
        if len(end):
            self.busy_until = int(end[-1])
        return (start + offset, delivered, marks,
                attempts._replace(on_air_ns=start[:, None] + attempts.on_air_ns, start_ns=start))

    def unicast(self, t_ns: int, nbytes: int,
                air: Callable[[Attempts], None] | None = None) -> tuple[bool, int, int]:
        """One packet offered at *t_ns*: (delivered, retries, latency_ns); the latency is to
        delivery, or to giving up when the packet is lost. *air* is given its attempts
        (``on_air_ns`` in true time)."""
        attempts = self._attempts(np.array([t_ns], dtype=np.int64),
                                  np.array([nbytes], dtype=np.int64))
        delivered, retries, offset, service = attempts[:4]
        if air is not None:
            air(attempts._replace(on_air_ns=t_ns + attempts.on_air_ns))
        ok = bool(delivered[0])
        return ok, int(retries[0]), int(offset[0] if ok else service[0])


class AirFrame(NamedTuple):
    """One frame on the air: its PSDU (MAC frame with FCS, protocols.ieee802154) and the
    true time of its first bit (preamble)."""

    t_ns: int
    psdu: bytes


class Sender:
    """A radio's data frames on the air, and its peer's ACKs of them.

    ZigBee counts the MAC sequence number, the NWK sequence number and the APS counter
    separately per radio; the radio sends nothing else that is modelled here (no route
    discovery, link status or APS ACKs), so all three count its packets, from 0 at power-on,
    modulo 256. A retry repeats the frame, its MAC sequence number included.
    """

    def __init__(self, pan: int, radius: int = zigbee.DEFAULT_RADIUS) -> None:
        self.pan = pan
        self.radius = radius
        self.sent = 0
        self._made: dict[tuple, list[bytes]] = {}  # the headers by addresses (_headers)

    def frames(self, attempts: Attempts, i: int, src16: int, dst16: int, data: bytes,
               radius: int | None = None, **aps) -> list[AirFrame]:
        """The air of packet *i* of *attempts* (Link.transmit's or unicast's) from *src16* to
        *dst16* carrying *data* (*radius*: when not the radio's; *aps*: endpoints, cluster
        and profile when not Digi's data endpoints, zigbee.data_packet): each attempt, and
        the ACK of the one received."""
        return self.block(attempts, np.array([i]), [src16], dst16, [data], radius, **aps)[0]

    def block(self, attempts: Attempts, which: np.ndarray, src16, dst16: int,
              payloads: list[bytes], radius: int | None = None, **aps) -> list[list[AirFrame]]:
        """:meth:`frames` of the packets *which* of *attempts*, in order, from *src16* (one
        per packet) carrying *payloads*: a block's air at once. Each data frame is its
        headers (:meth:`_headers`), its data and the FCS of both, a few C calls: numpy's
        calls on rows of a block's 100 packets cost as much as building each with struct
        and crc_hqx (measured: 110 us against 107), and the headers made once halve that;
        the attempts and ACKs are numpy's (:meth:`_air`)."""
        seqs = [(self.sent + j) & 0xFF for j in range(len(payloads))]
        self.sent += len(payloads)
        radius = self.radius if radius is None else radius
        headers = {my: self._headers(dst16, my, radius, aps) for my in set(src16)}
        psdus = [ieee802154.with_fcs(headers[my][seq] + data)
                 for seq, my, data in zip(seqs, src16, payloads)]
        return self._air(attempts, which, psdus, seqs)

    def _headers(self, dst16: int, src16: int, radius: int, aps: dict) -> list[bytes]:
        """The MAC, NWK and APS headers of a data frame from *src16* to *dst16*, one per
        sequence number (MAC, NWK and APS count together): the frame builders' with no data
        and no FCS (the data is the last field of each layer), made once per addresses."""
        key = (dst16, src16, radius, tuple(sorted(aps.items())))
        if key not in self._made:
            self._made[key] = [ieee802154.data_frame(seq, self.pan, dst16, src16, zigbee.data_packet(
                dst16, src16, radius, seq, seq, b"", **aps))[:-ieee802154.FCS_BYTES] for seq in range(256)]
        return self._made[key]

    @staticmethod
    def _air(attempts: Attempts, which: np.ndarray, psdus: list[bytes], seqs) -> list[list[AirFrame]]:
        """Per packet *which[j]* (carrying *psdus[j]*, MAC sequence number *seqs[j]*), its
        frames on the air in time order: each attempt it made, and after the last one, when
        it was received, the ACK (the attempts before it were lost: Link stops at the first
        received). A table of (packet, attempt or ACK) cells, taken row by row where made."""
        count, tries = attempts.count[which], attempts.on_air_ns.shape[1]
        m = len(which)
        times = np.empty((m, tries + 1), dtype=np.int64)
        times[:, :tries] = attempts.on_air_ns[which]
        times[:, tries] = times[np.arange(m), count - 1] + attempts.air_ns[which] + TURNAROUND_NS
        made = np.empty((m, tries + 1), dtype=bool)
        made[:, :tries] = np.arange(tries) < count[:, None]
        made[:, tries] = attempts.delivered[which]
        # each cell's frame in psdus + acks: packet j's data frame j, its ACK m + j
        cell = np.arange(m)[:, None] + np.where(np.arange(tries + 1) < tries, 0, m)
        pool = psdus + [ieee802154.ack_frame(s) for s in seqs]
        flat = rows(AirFrame, times[made].tolist(), map(pool.__getitem__, cell[made].tolist()))
        ends = np.cumsum(made.sum(axis=1)).tolist()
        return [flat[a:b] for a, b in zip([0] + ends[:-1], ends)]
