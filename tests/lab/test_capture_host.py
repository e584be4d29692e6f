"""A host recording as navtwin host writes it (navtwin.host.bench.write_host_recording: the
meta of host.service, its xbee.tx port) written as a capture: wall time, and what the host sent
to the coordinator outbound on the xbee interface (issue 19 item 5)."""
from navtwin.host.bench import write_host_recording
from navtwin.host.service import TX_PORT
from navtwin.host.tracks import BUILT_IN
from navtwin.protocols import xbee
from navtwin.protocols.capture import write_recording
from navtwin.protocols.pcapng import INBOUND, OUTBOUND
from navtwin.protocols.recording import Recording

from ..helpers import OFFICE
from ..tshark import fields, packets
from . import lab_bytes


def test_the_hosts_writes_are_outbound_on_xbee_and_its_reads_inbound(tmp_path):
    query = xbee.build(0x08, frame_id=1, command=b"DB", parameter=b"")
    chunks = lab_bytes.office(1.0, 4)
    path = write_host_recording(tmp_path / "host", OFFICE, BUILT_IN, chunks)
    # its query, sent before the first read, as the host records one (no read columns)
    (path / f"{TX_PORT}.bin").write_bytes(query)
    with open(path / f"{TX_PORT}.csv", "a") as f:
        f.write(f"0,{len(query)},,1,,,\n")
    chunks.insert(0, (TX_PORT, query, 1))
    capture = tmp_path / "host.pcapng"
    with open(capture, "wb") as f:
        written = write_recording(Recording(path), f)
    assert written.clock == "wall" and set(written.packets) == {"xbee", "nanoloc"}
    rows = packets(capture)
    for port, direction, source in (("xbee", OUTBOUND, TX_PORT), ("xbee", INBOUND, "xbee"),
                                    ("nanoloc", INBOUND, "nanoloc")):
        mine = [r for r in rows if r["interface"] == port and r["direction"] == direction]
        assert b"".join(r["data"] for r in mine) == b"".join(
            d for p, d, _ in chunks if p == source)
    assert rows[0]["direction"] == OUTBOUND
    assert fields(capture, "navtwin.xbee.command", where="frame.packet_flags_direction == 2") \
        == [[["DB"]]]
