"""The live tap (emulator.tap): a client reads every chunk as the lab delivers it, byte for byte
what the recording keeps, and what the host writes; a client that falls behind is dropped
without holding the lab up."""
import os
import select
import socket
import stat
import threading

import pytest

from navtwin.emulator import extcap
from navtwin.emulator.api import emulate
from navtwin.emulator.control import Control
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.tap import FORMAT, TapClient, TapError, TapServer
from navtwin.protocols.capture import UNDISSECTED
from navtwin.protocols.pcapng import LINKTYPE_IEEE802_15_4_WITHFCS, LINKTYPE_USER0
from navtwin.protocols.recording import Recording

from ..cli.test_extcap import read_pcapng

DEADLINE_S = 20.0
#: ATMY as the host sends it (API frame 0x08, frame id 1)
ATMY = bytes.fromhex("7E00040801") + b"MY" + b"\x50"


def _collect(client: TapClient, into: dict) -> None:
    for r in client.records():
        into.setdefault((r.name, r.direction), []).append(r)


def test_a_client_from_the_start_reads_the_recording_byte_for_byte(tmp_path):
    emu = Emulation(load_scenario("office"), 7, speed=None, duration_s=10,
                    link_dir=tmp_path / "links", record=tmp_path / "rec")
    got: dict = {}
    with emu:
        tap = tmp_path / "links" / "tap"
        assert stat.S_ISSOCK(os.lstat(tap).st_mode) and stat.S_IMODE(os.lstat(tap).st_mode) == 0o600
        assert emu.info()["tap"] == str(tap)
        client = TapClient(tmp_path / "links")  # in the backlog: the loop's first turn takes it
        reader = threading.Thread(target=_collect, args=(client, got))
        reader.start()
        emu.run()
    reader.join(DEADLINE_S)
    assert not reader.is_alive() and client.ended
    assert not tap.exists()  # removed with the run
    hello = client.hello
    rec = Recording(tmp_path / "rec")
    assert hello["format"] == FORMAT and hello["ports"] == rec.meta["ports"]
    assert (hello["scenario"], hello["seed"], hello["speed"]) == ("office", 7, "max")
    assert hello["offsets"] == {p: 0 for p in rec.meta["ports"]}
    for port in rec.meta["ports"]:
        records = got[(port, "to_host")]
        assert b"".join(r.data for r in records) == rec.read_bytes(port)
        # one record per recorded chunk, at its device time
        assert [(r.t_device_ns, len(r.data)) for r in records] == \
            [(c.t_device_ns, len(c.data)) for c in rec.chunks(port)]
    # the air, a declared stream: every frame the recording keeps, at its device time
    assert hello["streams"] == {"air": rec.meta["streams"]["air"]}
    assert [(r.t_device_ns, r.data) for r in got[("air", None)]] == \
        [(c.t_device_ns, c.data) for c in rec.chunks("air")]
    assert not [k for k in got if k[1] == "to_device"]  # no host wrote anything


def test_a_running_lab_taps_host_writes_and_the_recording_from_the_hello_offsets(tmp_path):
    with emulate("office", seed=3, duration=3, record=tmp_path / "rec") as lab:
        client = TapClient(lab.info["link_dir"], timeout=DEADLINE_S)
        assert client.hello["offsets"]["sins"] >= 0
        assert lab.status()["tap"]["clients"] == 1
        fd = os.open(lab.ports["xbee"], os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(fd, ATMY)
            got: dict = {}
            _collect(client, got)  # until the run's end record
        finally:
            os.close(fd)
        lab.wait_done(DEADLINE_S)
    assert client.ended
    written = got[("xbee", "to_device")]
    assert b"".join(r.data for r in written) == ATMY
    assert all(r.t_wall_ns > 0 for r in written)
    rec = Recording(tmp_path / "rec")
    for port, offset in client.hello["offsets"].items():
        assert b"".join(r.data for r in got[(port, "to_host")]) == rec.read_bytes(port)[offset:]
        # paced: the wall times are the recording's
        tail = [c for c in rec.chunks(port) if c.offset >= offset]
        assert [r.t_wall_ns for r in got[(port, "to_host")]] == [c.t_wall_ns for c in tail]


def test_a_client_that_does_not_read_is_dropped_and_the_lab_runs_on(tmp_path):
    emu = Emulation(load_scenario("office"), 7, speed=None, duration_s=60,
                    link_dir=tmp_path / "links", record=tmp_path / "rec")
    with emu:
        emu.tap.max_buffer = 4096
        idle = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        idle.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        idle.connect(str(tmp_path / "links" / "tap"))
        summary = emu.run()
        assert emu.tap.status()["dropped"] == 1 and emu.tap.status()["clients"] == 0
        assert emu._op_status(None)["tap"]["dropped"] == 1
    assert summary["virtual_s"] == 60 and not summary["interrupted"]
    # it got the hello and a prefix, then a close with no end record
    idle.settimeout(DEADLINE_S)
    data = b""
    while chunk := idle.recv(1 << 16):
        data += chunk
    idle.close()
    assert data.startswith(b'{"format":"navtwin-tap"')
    rec = Recording(tmp_path / "rec")
    assert len(data) < sum(len(rec.read_bytes(p)) for p in rec.meta["ports"])


def test_no_lab_is_one_line_naming_the_fix(tmp_path):
    with pytest.raises(TapError, match=r"^link_dir: .*tap: cannot connect \(no such socket\); "
                                       r"is an emulator running"):
        TapClient(tmp_path)


def test_a_stream_that_is_not_a_port_reaches_the_capture_on_its_own_interface(tmp_path):
    """The air (another part of the lab) declares its stream and sends packets through
    ``tap.stream``: a reader learns its link type, and the extcap writes it as an interface."""
    server = TapServer(tmp_path / "tap", lambda: {"ports": {"sins": {"baud": 115200}}},
                       lambda: 42)
    server.declare("air", LINKTYPE_IEEE802_15_4_WITHFCS, "the radio")
    out = tmp_path / "air.pcapng"
    result: list = []
    capture = threading.Thread(target=lambda: result.append(extcap.capture(tmp_path, out)))
    capture.start()
    assert select.select([server.sock], [], [], DEADLINE_S)[0], "the capture did not connect"
    server.serve([server.sock])
    assert server.status()["clients"] == 1
    server.stream("air", 1_000, b"\x41\x88frame")
    server.chunk("sins", "to_host", 2_000, b"\xaa\x55")
    server.declare("later", UNDISSECTED, "declared while a reader is connected")
    server.stream("later", 3_000, b"x")
    server.close()  # the end record: the capture ends
    capture.join(DEADLINE_S)
    assert result == [True]
    interfaces, packets = read_pcapng(out.read_bytes())
    assert interfaces == [("air", LINKTYPE_IEEE802_15_4_WITHFCS), ("sins", LINKTYPE_USER0),
                          ("later", UNDISSECTED)]
    assert [(i, t, d) for i, t, _, d in packets] == [(0, 1_000, b"\x41\x88frame"),
                                                     (1, 2_000, b"\xaa\x55"), (2, 3_000, b"x")]
