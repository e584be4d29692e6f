"""``navtwin emulate --rfc2217``: pyserial's rfc2217:// client on the lab's ports."""
from __future__ import annotations

import json
import random
import select
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest
import serial

from navtwin.emulator.rfc2217 import Session
from navtwin.protocols.stream import DecodeError, Frame, sins_decoder

from ..helpers import NAVTWIN, navtwin, one_line_error

DEADLINE = 30.0
PORTS = ("sins", "xbee", "nanoloc")


def free_range(n: int = len(PORTS)) -> int:
    """A first TCP port with *n* free loopback ports from it (the server binds PORT.. PORT+n-1)."""
    for _ in range(100):
        first = random.randrange(20000, 60000)
        socks = []
        try:
            for i in range(n):
                s = socket.socket()
                socks.append(s)
                s.bind(("127.0.0.1", first + i))
            return first
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free range of loopback TCP ports")


def start(tmp_path, *args):
    first = free_range()
    proc = subprocess.Popen([*NAVTWIN, "emulate", "--scenario", "office", "--seed", "7",
                             "--rfc2217", f"127.0.0.1:{first}", "--link-dir", tmp_path / "l",
                             "--quiet", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    return first, proc


@pytest.fixture
def lab(tmp_path):
    first, proc = start(tmp_path)
    try:
        assert select.select([proc.stdout], [], [], DEADLINE)[0]
        yield first, json.loads(proc.stdout.readline())
    finally:
        proc.terminate()
        proc.communicate(timeout=DEADLINE)


def read_sins(url: str, baud: int, n: int = 3000) -> tuple[list, list]:
    """*n* bytes of the SINS port read at *baud*; its (frames, decode errors)."""
    with serial.serial_for_url(url, baudrate=baud, timeout=0.5) as port:
        data = b""
        deadline = time.monotonic() + DEADLINE
        while len(data) < n and time.monotonic() < deadline:
            data += port.read(n - len(data))
    assert len(data) == n, "the port gave too few bytes before the deadline"
    events = sins_decoder().decode(data)
    return ([e for e in events if isinstance(e, Frame)],
            [e for e in events if isinstance(e, DecodeError)])


@pytest.mark.pty
def test_ready_line_lists_one_url_per_port_in_the_labs_order(lab):
    first, ready = lab
    assert list(ready["rfc2217"]) == list(PORTS)
    assert ready["rfc2217"] == {p: f"rfc2217://127.0.0.1:{first + i}"
                                for i, p in enumerate(PORTS)}


@pytest.mark.pty
def test_pyserial_at_the_ports_rate_reads_crc_valid_sins_frames(lab):
    _, ready = lab
    frames, errors = read_sins(ready["rfc2217"]["sins"], 115200)
    assert len(frames) >= 100  # 3000 bytes of 26-byte frames, the first maybe cut
    assert [f.type for f in frames] == [frames[0].type] * len(frames)
    assert any(0xFF in f.raw for f in frames)  # sent as IAC IAC, read back as one byte
    assert sum(1 for e in errors if e.kind != "garbage") == 0


@pytest.mark.pty
def test_a_client_at_9600_baud_reads_garbage(lab):
    _, ready = lab
    frames, errors = read_sins(ready["rfc2217"]["sins"], 9600, n=1500)
    assert frames == [] and errors


@pytest.mark.pty
def test_settings_are_answered_with_the_values_in_force(lab):
    """The raw protocol: 0xFF in a value is doubled, 0 asks, server codes are +100."""
    _, ready = lab
    port = int(ready["rfc2217"]["nanoloc"].rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=DEADLINE) as s:
        iac, sb, se = 255, 250, 240
        s.sendall(bytes([iac, 251, 44,  # WILL COM-PORT-OPTION
                         iac, sb, 44, 1, 0, 0, 0x4B, 0, iac, se,  # SET-BAUDRATE 19200
                         iac, sb, 44, 1, 0, 0, 0, 0, iac, se,  # ... and ask for it
                         iac, sb, 44, 5, 8, iac, se]))  # SET-CONTROL DTR on
        want = [bytes([iac, sb, 44, 101, 0, 0, 0x4B, 0, iac, se])] * 2 + \
            [bytes([iac, sb, 44, 105, 8, iac, se])]
        got = b""
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline and not all(w in got for w in want):
            got += s.recv(4096)
    assert bytes([iac, 253, 44]) in got  # DO COM-PORT-OPTION
    assert got.count(want[0]) == 2 and want[2] in got


def test_bad_address_is_one_line_with_exit_2(tmp_path):
    one_line_error(navtwin("emulate", "--scenario", "office", "--rfc2217", "host:99999",
                           "--link-dir", tmp_path / "l"), "[HOST:]PORT")


@pytest.mark.pty
@pytest.mark.slow
def test_navtwin_host_on_rfc2217_gets_the_labs_bytes_and_its_estimates(tmp_path):
    """The host on all three ports over RFC 2217 records exactly a stretch of what the
    devices sent (the emulator's own recording), and its estimates replay from that
    recording byte for byte: the same bytes as on the PTYs, so the same estimates."""
    _, proc = start(tmp_path, "--record", tmp_path / "emu")
    try:
        assert select.select([proc.stdout], [], [], DEADLINE)[0]
        urls = json.loads(proc.stdout.readline())["rfc2217"]
        host = navtwin("host", *(a for p in PORTS for a in (f"--{p}", urls[p])),
                       "--duration", "4", "--out", tmp_path / "live.jsonl",
                       "--record", tmp_path / "rec")
        assert host.returncode == 0, host.stderr
    finally:
        proc.terminate()
        proc.communicate(timeout=DEADLINE)
    for p in PORTS:
        got = (tmp_path / "rec" / f"{p}.bin").read_bytes()
        assert len(got) > 1000 and got in (tmp_path / "emu" / f"{p}.bin").read_bytes(), p
    live = (tmp_path / "live.jsonl").read_text()
    assert {json.loads(x)["filter"] for x in live.splitlines()} >= {"sins", "kf", "ekf", "ukf"}
    replay = navtwin("replay", tmp_path / "rec")
    assert replay.returncode == 0, replay.stderr
    assert replay.stdout == live


def test_the_parser_undoubles_iac_and_drops_commands_across_reads():
    """Towards the device: IAC IAC is one data 0xFF, other commands are no data, even
    when a read ends inside them (the parser keeps its state between reads)."""
    session = Session(None, Path("unused"), threading.Event())
    stream = (b"\x01\xff\xff\x02\xff\xf1\x03"  # data 01 FF 02, a NOP, data 03
              b"\xff\xfa\x2c\x0c\x03\xff\xf0")  # PURGE-DATA (answered, not data)
    answered = []
    session._subnegotiation = answered.append
    got = b"".join(session._telnet(stream[i:i + 1]) for i in range(len(stream)))
    assert got == b"\x01\xff\x02\x03" and answered == [b"\x2c\x0c\x03"]


@pytest.mark.pty
def test_a_clients_rate_ends_with_its_connection(lab):
    _, ready = lab
    read_sins(ready["rfc2217"]["sins"], 9600, n=100)
    with open(ready["ports"]["sins"], "rb", buffering=0) as local:  # sets no termios
        data = b""
        deadline = time.monotonic() + DEADLINE
        while len(data) < 300 and time.monotonic() < deadline:
            assert select.select([local], [], [], DEADLINE)[0]
            data += local.read(300)
    assert [e for e in sins_decoder().decode(data) if isinstance(e, Frame)]


def test_a_tcp_port_in_use_is_one_line_with_exit_2(tmp_path):
    first = free_range()
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", first + 1))  # the xbee port's
        taken.listen(1)
        one_line_error(navtwin("emulate", "--scenario", "office", "--rfc2217", str(first),
                               "--link-dir", tmp_path / "l"), f"{first + 1}", "choose other")
    assert not (tmp_path / "l").exists()  # links and directory removed on the way out
