"""``navtwin pcap`` (issue 19 item 5): a recording as a capture, one summary line, the Lua
file's path, and bad input as one line before the output is touched (more bad input:
test_bad_input.py). What the capture holds is tests/protocols/test_capture.py's."""
from __future__ import annotations

import subprocess

import pytest

from navtwin.protocols import xbee
from navtwin.protocols.capture import dissectors_path
from navtwin.protocols.recording import Recording, RecordingWriter
from navtwin.protocols.stream import Frame, sins_decoder

from .. import recorded
from ..helpers import DEADLINE_S, navtwin, one_line_error
from ..tshark import fields, tshark

PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return recorded.office(tmp_path_factory.mktemp("pcap") / "run", 3)


def test_dissectors_prints_the_shipped_lua_file():
    p = navtwin("pcap", "--dissectors")
    assert p.returncode == 0, p.stderr
    assert p.stdout == f"{dissectors_path()}\n" and dissectors_path().is_file()


def test_a_recording_becomes_a_capture_tshark_decodes_with_the_printed_lua(run, tmp_path):
    out = tmp_path / "run.pcapng"
    p = navtwin("pcap", run, "-o", out)
    assert p.returncode == 0 and p.stdout == "", p.stderr
    rec = Recording(run)
    # every port and the air, each interface declared with its first packet
    names = ("xbee", "sins", "air", "nanoloc")
    chunks = {name: list(rec.chunks(name)) for name in names}
    assert p.stderr == (f"navtwin pcap: {out}: {sum(map(len, chunks.values()))} packets, "
                        "device time: " + ", ".join(
                            f"{name} {len(c)} packets ({sum(len(x.data) for x in c)} bytes)"
                            for name, c in chunks.items()) + "\n")
    lua = navtwin("pcap", "--dissectors").stdout.strip()
    shown = subprocess.run([tshark(), "-r", out, "-X", f"lua_script:{lua}"], capture_output=True,
                           text=True, timeout=DEADLINE_S, check=True).stdout
    assert "SINS seq 199" in shown and "XBee receive_packet (SINS seq 0)" in shown
    assert "nanoLOC anchor 1" in shown
    # the air: Wireshark's own 802.15.4 and ZigBee dissectors, the router's transparent data
    # (APS profile 0xC105) dissected as the board's SINS frames by ours
    air = fields(out, "wpan.fcs_ok", "zbee_aps.profile", "navtwin.sins.seq",
                 "navtwin.sins.crc_ok", where='frame.interface_name == "air" && zbee_aps')
    assert air and all(r[:2] == [["1"], ["0xc105"]] and r[3] == ["1"] * len(r[2]) for r in air)
    # every attempt is on the air: a retry repeats the packet before it
    on_air = [int(seq) for i, r in enumerate(air) if i == 0 or r[2] != air[i - 1][2]
              for seq in r[2]]
    board = [e.fields["seq"] for e in sins_decoder().decode(rec.read_bytes("sins"))
             if isinstance(e, Frame)]
    assert on_air == board[:len(on_air)] and len(on_air) > 100  # in order, none lost
    # to stdout, for a pipe into wireshark -k -i -: the same bytes
    piped = navtwin("pcap", run, "-o", "-", text=False)
    assert piped.returncode == 0 and piped.stdout == out.read_bytes()
    assert out.read_bytes().startswith(PCAPNG_MAGIC)


def test_a_host_recording_is_written_on_its_wall_clock_and_says_so(tmp_path):
    with RecordingWriter(tmp_path / "host", {"ports": {"xbee": {}, "xbee.tx": {"of": "xbee"}}},
                         reads=True) as w:
        w.port("xbee.tx").write(xbee.build(0x08, frame_id=1, command=b"AP", parameter=b""),
                                t_wall_ns=5)
    p = navtwin("pcap", tmp_path / "host", "-o", tmp_path / "h.pcapng")
    assert p.returncode == 0, p.stderr
    assert "1 packets, wall time: xbee 1 packets (8 bytes) (the recording has no device " \
           "times)" in p.stderr


def test_a_damaged_recording_is_one_line_and_leaves_the_output_alone(run, tmp_path):
    damaged = recorded.copy(run, tmp_path / "damaged")
    with open(damaged / "sins.csv", "a") as f:
        f.write("not,an,index,line\n")
    out = tmp_path / "old.pcapng"
    out.write_bytes(b"an earlier capture")
    line = one_line_error(navtwin("pcap", damaged, "-o", out), "sins.csv", "damaged")
    assert "Traceback" not in line and out.read_bytes() == b"an earlier capture"
