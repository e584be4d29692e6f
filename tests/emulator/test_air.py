"""The radio hop on the air: the recording's air stream against the xbee port it explains.

Each delivered packet is a data frame whose APS payload is the RF data of a 0x90 frame on the
coordinator's port, on the air before the coordinator writes it; a retry repeats the frame
with its MAC sequence number; a lost attempt has no ACK; Wireshark reads it all.
"""
from __future__ import annotations

import subprocess
from dataclasses import dataclass

import pytest

from navtwin.emulator.runner import AIR, Emulation
from navtwin.protocols import ieee802154, xbee, zigbee
from navtwin.protocols.capture import write_recording
from navtwin.protocols.pcapng import LINKTYPE_IEEE802_15_4_WITHFCS
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import XBeeDecoder
from navtwin.protocols.xbee import FrameType

from ..tshark import tshark
from .world_helpers import variant

SEED = 7


@dataclass
class Attempt:
    t_ns: int
    seq: int
    src: int
    nwk_seq: int
    aps_counter: int
    data: bytes
    acked_at: int | None = None


def recorded(tmp_path, faults: str = "", duration_s: float = 4.0):
    """A recorded run of office; the air sink must have been given the recorded air."""
    sc = variant(tmp_path, "office", f"duration_s = {duration_s}\n{faults}")
    sunk: list = []
    with Emulation(sc, SEED, speed=None, ports=False, record=tmp_path / "rec",
                   air_sink=sunk.append) as emu:
        emu.run()
    rec = Recording(tmp_path / "rec")
    assert [(f.t_ns, f.psdu) for f in sunk] == [(c.t_device_ns, c.data) for c in rec.chunks(AIR)]
    return rec


def attempts(rec: Recording) -> list[Attempt]:
    """The air's data frames, each with the time of its ACK (the next frame, when it is one)."""
    out: list[Attempt] = []
    for chunk in rec.chunks(AIR):
        psdu = chunk.data
        assert ieee802154.fcs(psdu) == 0  # FCS residue: every frame intact
        mac = ieee802154.DataFrame.parse(psdu[:-2]) if psdu[:2] == ieee802154.DATA_FC else None
        if mac is None:
            ack = ieee802154.AckHeader.parse(psdu[:-2])
            last = out[-1]
            assert ack.seq == last.seq and last.acked_at is None
            last.acked_at = chunk.t_device_ns
            continue
        packet = zigbee.DataPacket.parse(mac.payload)
        assert (mac.header.dst, packet.nwk.dst, packet.nwk.src, packet.nwk.radius) == \
            (zigbee.COORDINATOR16, zigbee.COORDINATOR16, mac.header.src, zigbee.DEFAULT_RADIUS)
        assert (packet.aps.cluster, packet.aps.profile) == (0x0011, 0xC105)
        out.append(Attempt(chunk.t_device_ns, mac.header.seq, mac.header.src, packet.nwk.seq,
                           packet.aps.counter, packet.data))
    return out


def received(rec: Recording) -> list[tuple[int, bytes, int]]:
    """(t_device_ns, RF data, source MY) of each 0x90 frame on the xbee port."""
    decoder, out = XBeeDecoder(escaped=rec.meta["ports"]["xbee"]["api_mode"] == 2), []
    for chunk in rec.chunks("xbee"):
        for f in decoder.decode(chunk.data):
            if f.type == FrameType.RECEIVE_PACKET:
                out.append((chunk.t_device_ns, f.fields["data"], f.fields["src16"]))
    return out


def packets(tries: list[Attempt]) -> list[list[Attempt]]:
    """Attempts grouped by packet: a retry repeats its packet's MAC sequence number."""
    out: list[list[Attempt]] = []
    for a in tries:
        if out and out[-1][-1].acked_at is None and a.seq == out[-1][-1].seq:
            assert (a.data, a.nwk_seq, a.aps_counter) == \
                (out[-1][-1].data, out[-1][-1].nwk_seq, out[-1][-1].aps_counter)
            out[-1].append(a)
        else:
            out.append([a])
    return out


def test_each_delivered_packet_is_a_0x90_frame_after_it_on_the_air(tmp_path):
    rec = recorded(tmp_path)
    assert rec.streams[AIR].linktype == LINKTYPE_IEEE802_15_4_WITHFCS and AIR not in rec.ports
    sent = packets(attempts(rec))
    delivered = [p for p in sent if p[-1].acked_at is not None]
    frames = received(rec)
    # the packets delivered in the run's last milliseconds reach the port after its end
    assert len(frames) > 300 and [p[-1].data for p in delivered[:len(frames)]] == \
        [d for _, d, _ in frames]
    assert all(p[-1].t_ns > 3.98e9 for p in delivered[len(frames):])
    for p, (t_uart, _, src16) in zip(delivered, frames):
        last = p[-1]
        air_end = last.t_ns + (len(last.data) + zigbee.OVERHEAD_BYTES) * ieee802154.BYTE_NS
        assert last.acked_at == air_end + ieee802154.TURNAROUND_NS
        assert last.t_ns < air_end < t_uart and last.src == src16
    # a new packet takes the next MAC seq, NWK seq and APS counter
    counters = [(p[0].seq, p[0].nwk_seq, p[0].aps_counter) for p in sent]
    assert counters == [(n & 0xFF,) * 3 for n in range(len(sent))]
    t = [c.t_device_ns for c in rec.chunks(AIR)]
    assert t == sorted(t)


def test_link_loss_shows_retries_and_lost_packets_without_acks(tmp_path):
    rec = recorded(tmp_path, '[[faults]]\nkind = "link_loss"\nstart_s = 2.0\nend_s = 2.5\n')
    sent = packets(attempts(rec))
    tries = 1 + rec_max_retries(tmp_path)
    lost = [p for p in sent if p[-1].acked_at is None]
    # inside the fault every attempt is sent and none is ACKed: the whole packet is lost
    assert len(lost) > 10 and all(len(p) == tries for p in lost)
    # (the fault acts on packets the router closes inside it; they queue, 4 attempts each)
    assert all(2.0e9 <= p[0].t_ns < 3.0e9 for p in lost)
    assert all(a.acked_at is None for p in lost for a in p)
    # retries outside the fault (per-attempt loss) end with an ACK
    assert any(len(p) > 1 and p[-1].acked_at is not None for p in sent)
    # lost packets are on the air, never on the port
    delivered = [p[-1].data for p in sent if p[-1].acked_at is not None]
    frames = [d for _, d, _ in received(rec)]
    assert delivered[:len(frames)] == frames and len(delivered) - len(frames) <= 1  # the end's


def rec_max_retries(tmp_path) -> int:
    return variant(tmp_path, "office", "", name="retries").link.max_retries




def test_wireshark_decodes_the_recorded_air(tmp_path):
    """The recording as navtwin pcap writes it: the air on an interface of its own, which
    Wireshark's own wpan, ZigBee NWK and APS dissectors decode; its data frames carry the
    board's SINS frames."""
    rec = recorded(tmp_path, duration_s=1.0)
    path = tmp_path / "run.pcapng"
    with open(path, "wb") as f:
        written = write_recording(rec, f)
    assert written.packets[AIR] == sum(1 for _ in rec.chunks(AIR)) > 100
    fields = ["wpan.frame_type", "wpan.fcs_ok", "wpan.seq_no", "zbee_nwk.src",
              "zbee_aps.profile", "zbee_aps.cluster", "zbee_aps.dst", "data.data"]
    text = subprocess.run([tshark(), "-r", str(path), "-Y", f'frame.interface_name == "{AIR}"',
                           "-T", "fields", "-E", "occurrence=l", *[a for f in fields for a in ("-e", f)]],
                          capture_output=True, text=True, check=True).stdout
    rows = [line.split("\t") for line in text.splitlines()]
    my = f"0x{received(rec)[0][2]:04x}"
    assert len(rows) == written.packets[AIR]
    assert all(r[1] == "1" for r in rows)  # every FCS good
    data = [r for r in rows if r[0] == "0x0001"]
    assert data and all(r[3:7] == [my, "0xc105", "0x0011", "232"] for r in data)
    assert {r[0] for r in rows} == {"0x0001", "0x0002"}  # data frames and their ACKs
    board = rec.read_bytes("sins")
    assert all(bytes.fromhex(r[7]) in board for r in data)  # a packet of the board's bytes


def test_the_coordinators_transmit_requests_are_on_the_air_in_time_order(tmp_path):
    """0x10 and 0x11 to the router: data frames from 0x0000 to the router's MY (a 0x11 with
    its endpoints, cluster, profile and radius), the router's ACK after a received attempt,
    merged into the recorded air in time order; the router's own frames as without them."""
    sc = variant(tmp_path, "office", "duration_s = 1.0\n")
    router = sc.routers_for(SEED)[0]
    dest64 = router["SH"] << 32 | router["SL"]
    requests = [(100_000_000, xbee.build(0x10, True, frame_id=1, dest64=dest64, dest16=0xFFFE,
                                         radius=0, options=0, data=b"hello router")),
                (300_000_000, xbee.build(0x11, True, frame_id=2, dest64=dest64, dest16=0xFFFE,
                                         src_endpoint=0xE8, dest_endpoint=0xE6,
                                         cluster=0x0021, profile=0xC105, radius=5, options=0,
                                         data=b"\x01AP"))]
    with Emulation(sc, SEED, speed=None, ports=False, record=tmp_path / "rec") as emu:
        for t, frame in requests:
            emu.inbounds["xbee"].put(t, frame)
        emu.run()
    rec = Recording(tmp_path / "rec")
    chunks = list(rec.chunks(AIR))
    assert [c.t_device_ns for c in chunks] == sorted(c.t_device_ns for c in chunks)
    down = []
    for i, c in enumerate(chunks):
        if c.data[:2] != ieee802154.DATA_FC:
            continue
        mac = ieee802154.DataFrame.parse(c.data[:-2])
        if mac.header.src == zigbee.COORDINATOR16:
            ack = chunks[i + 1].data if i + 1 < len(chunks) else b""
            down.append((c.t_device_ns, mac.header.dst, zigbee.DataPacket.parse(mac.payload),
                         ack == ieee802154.ack_frame(mac.header.seq)))
    assert [d[2].data for d in down if d[3]] == [b"hello router", b"\x01AP"]
    (t1, dst1, first, _), (t2, dst2, second, _) = [d for d in down if d[3]]
    assert dst1 == dst2 == router["MY"] and 100e6 <= t1 < 200e6 and 300e6 <= t2 < 400e6
    assert (first.nwk.radius, first.aps.dst_endpoint, first.aps.cluster) == (0x1E, 0xE8, 0x0011)
    assert (second.nwk.radius, second.aps.dst_endpoint, second.aps.src_endpoint,
            second.aps.cluster, second.aps.profile) == (5, 0xE6, 0xE8, 0x0021, 0xC105)
    # the coordinator counts its own frames
    assert (first.nwk.seq, second.nwk.seq) == (0, 1)
    # the router's packets are on the air as in a run without the host
    (tmp_path / "alone").mkdir()
    alone = recorded(tmp_path / "alone", duration_s=1.0)
    assert routers(chunks) == routers(list(alone.chunks(AIR))) != []


def routers(chunks) -> list[tuple[int, bytes]]:
    """The router's data frames among *chunks* of the air, with their times."""
    return [(c.t_device_ns, c.data) for c in chunks if c.data[:2] == ieee802154.DATA_FC
            and ieee802154.DataFrame.parse(c.data[:-2]).header.src != zigbee.COORDINATOR16]
