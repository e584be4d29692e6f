"""Real clients on the emulator's PTYs: pyserial, digi-xbee, python-xbee, socat, picocom.

Each test starts ``navtwin emulate --speed realtime`` as a subprocess (emulator.api) and
talks to the stable links. Waits are on data or conditions with generous deadlines.
"""
import os
import select
import shutil
import subprocess
import threading
import time

import pytest
import serial

from navtwin.emulator.api import emulate
from navtwin.emulator.scenario import load_scenario
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import (DecodeError, Frame, XBeeDecoder, XBeeSinsChain, nanoloc_decoder,
                              sins_decoder)

pytestmark = pytest.mark.pty
DEADLINE = 20.0
ROUTER = load_scenario("office").radios_for(load_scenario("office").seed)["router"]
ROUTER64 = ROUTER["SH"] << 32 | ROUTER["SL"]


@pytest.fixture
def lab():
    with emulate("office", speed="realtime", duration=60) as lab:
        yield lab


def read_frames(ser, decoder, n, deadline=DEADLINE):
    """Decode what *ser* delivers until *n* frames arrived; returns (frames, errors)."""
    frames, errors = [], []
    end = time.monotonic() + deadline
    while len(frames) < n and time.monotonic() < end:
        for ev in decoder.feed(ser.read(ser.in_waiting or 1)):
            (frames if isinstance(ev, Frame) else errors).append(ev)
    return frames, errors


def test_pyserial_reads_valid_sins_frames_without_gaps(lab):
    with serial.Serial(lab.ports["sins"], 115200, timeout=1) as ser:
        frames, errors = read_frames(ser, sins_decoder(), 200)
    assert len(frames) >= 200  # one read may finish more than one frame
    assert [e.kind for e in errors] in ([], ["garbage"])  # at most a partial first frame
    seqs = [f.fields["seq"] for f in frames]
    assert all((b - a) % 65536 == 1 for a, b in zip(seqs, seqs[1:]))


def test_reopened_port_delivers_fresh_bytes_not_stale_ones(lab):
    with serial.Serial(lab.ports["sins"], 115200, timeout=1) as ser:
        before, _ = read_frames(ser, sins_decoder(), 20)
    # let at least half a second pass while nobody reads the sins port: wait for 20
    # nanoLOC reports (40 per second) on another port rather than sleeping
    with serial.Serial(lab.ports["nanoloc"], 115200, timeout=1) as ser:
        reports, _ = read_frames(ser, nanoloc_decoder(), 20)
    assert len(reports) >= 20  # one read may finish several (a loaded box batches them)
    # opened with os.open: no pyserial input flush, so any stale byte would be read
    fd = os.open(lab.ports["sins"], os.O_RDONLY | os.O_NOCTTY)
    try:
        dec, after = sins_decoder(), []
        end = time.monotonic() + DEADLINE
        while not after and time.monotonic() < end:
            if select.select([fd], [], [], 1.0)[0]:
                after = [e for e in dec.feed(os.read(fd, 4096)) if isinstance(e, Frame)]
    finally:
        os.close(fd)
    gap = (after[0].fields["seq"] - before[-1].fields["seq"]) % 65536
    assert gap >= 40  # >= 0.4 s of frames skipped: nothing queued while unplugged


def test_digi_xbee_open_role_data_and_transmit(lab):
    from digi.xbee.devices import RemoteZigBeeDevice, XBeeDevice
    from digi.xbee.models.address import XBee64BitAddress
    from digi.xbee.models.mode import OperatingMode
    from digi.xbee.models.protocol import Role, XBeeProtocol
    from digi.xbee.models.status import TransmitStatus

    dev = XBeeDevice(lab.ports["xbee"], 115200)
    # a client setting: digi-xbee's 4 s per AT round trip, which a starved box can exceed;
    # how fast open() is (goal 1.5 s) is navtwin bench digi-open's to measure
    dev.set_sync_ops_timeout(DEADLINE)
    dev.open()
    try:
        assert dev.get_role() == Role.COORDINATOR
        assert dev.get_protocol() == XBeeProtocol.ZIGBEE
        assert dev.operating_mode == OperatingMode.ESCAPED_API_MODE
        assert str(dev.get_64bit_addr()) == "0013A20040A1B2C3"
        assert dev.get_node_id() == "LAB-COORD"

        chain, frames, cond = sins_decoder(), [], threading.Condition()

        def received(msg):
            assert msg.remote_device.get_64bit_addr().address == ROUTER64.to_bytes(8, "big")
            with cond:
                frames.extend(e for e in chain.feed(bytes(msg.data)) if isinstance(e, Frame))
                cond.notify_all()

        dev.add_data_received_callback(received)
        with cond:
            assert cond.wait_for(lambda: len(frames) >= 100, timeout=DEADLINE)
        assert all(f.format == "sins" and f.fields["seq"] is not None for f in frames)

        remote = RemoteZigBeeDevice(dev, XBee64BitAddress(ROUTER64.to_bytes(8, "big")))
        status = dev.send_data(remote, b"hello router")
        assert status.transmit_status == TransmitStatus.SUCCESS
        assert status.x16bit_dest_addr.address == ROUTER["MY"].to_bytes(2, "big")

        dev.set_parameter("NI", b"BENCH-1")
        assert dev.get_parameter("NI") == bytearray(b"BENCH-1")
        assert remote.get_parameter("NI") == bytearray(b"SINS-ROUTER")  # remote AT 0x17
        dev.reset()  # FR: OK, then modem status 0x01 within 5 s
    finally:
        dev.close()


def test_digi_xbee_reads_the_remote_router_as_an_s2b_router(lab):
    """read_device_info on the router: every AT read answered (CE: "invalid command", as ZB
    2x7x has none), then the ZDO node descriptor gives the role; then the I/O settings."""
    from digi.xbee.devices import RemoteZigBeeDevice, XBeeDevice
    from digi.xbee.io import IOLine, IOMode
    from digi.xbee.models.address import XBee64BitAddress
    from digi.xbee.models.protocol import Role

    dev = XBeeDevice(lab.ports["xbee"], 115200)
    dev.set_sync_ops_timeout(DEADLINE)  # digi-xbee's 4 s, which a starved box can exceed
    dev.open()
    answers = []  # (command, status) of every 0x97

    def remote_at_answer(packet):
        if packet.get_frame_type_value() == 0x97:
            answers.append((packet.command, packet.status))

    try:
        dev.add_packet_received_callback(remote_at_answer)
        remote = RemoteZigBeeDevice(dev, XBee64BitAddress(ROUTER64.to_bytes(8, "big")))
        reader = threading.Thread(target=remote.read_device_info, daemon=True)
        t = time.perf_counter()
        reader.start()
        reader.join(DEADLINE)  # the answer-less ZDO fallback took 2 x 12 s
        print(f"read_device_info on the router took {time.perf_counter() - t:.3f} s")
        assert not reader.is_alive()
        assert remote.get_role() == Role.ROUTER
        assert remote.get_node_id() == "SINS-ROUTER"
        assert remote.get_16bit_addr().address == ROUTER["MY"].to_bytes(2, "big")
        assert {c for c, _ in answers} >= {"HV", "VR", "SH", "SL", "NI", "MY", "CE"}
        assert all(s.code == 0 for c, s in answers if c != "CE")
        assert all(s.code == 2 for c, s in answers if c == "CE")

        # what digi-xbee's I/O API reads, with the S2B's factory defaults
        io = {line: remote.get_io_configuration(line) for line in (
            IOLine.DIO0_AD0, IOLine.DIO1_AD1, IOLine.DIO2_AD2, IOLine.DIO3_AD3,
            IOLine.DIO4_AD4, IOLine.DIO5_AD5, IOLine.DIO6, IOLine.DIO7,
            IOLine.DIO10_PWM0, IOLine.DIO11_PWM1, IOLine.DIO12)}
        special = {IOLine.DIO0_AD0, IOLine.DIO5_AD5, IOLine.DIO7, IOLine.DIO10_PWM0}
        assert io == {line: IOMode.SPECIAL_FUNCTIONALITY if line in special else IOMode.DISABLED
                      for line in io}
        assert remote.get_io_sampling_rate() == 0  # IR: no periodic sampling
        assert remote.get_parameter("IC") == bytearray(2)  # no line monitored for changes
    finally:
        dev.close()


def test_python_xbee_reads_rx_frames_and_answers(lab):
    from xbee import ZigBee

    with serial.Serial(lab.ports["xbee"], 115200, timeout=1) as ser:
        zb = ZigBee(ser, escaped=True)
        dec, frames = sins_decoder(), []

        def until(pred):
            end = time.monotonic() + DEADLINE
            while time.monotonic() < end:
                f = zb.wait_read_frame(timeout=DEADLINE)
                if f["id"] == "rx":
                    assert f["source_addr_long"] == ROUTER64.to_bytes(8, "big")
                    frames.extend(e for e in dec.feed(f["rf_data"]) if isinstance(e, Frame))
                if pred(f):
                    return f
            raise AssertionError("no such frame before the deadline")

        until(lambda f: len(frames) >= 30)
        zb.at(frame_id=b"\x01", command=b"VR")
        f = until(lambda f: f["id"] == "at_response")
        assert (f["frame_id"], f["command"], f["status"], f["parameter"]) == \
            (b"\x01", b"VR", b"\x00", b"\x21\xa7")
        zb.remote_at(frame_id=b"\x02", dest_addr_long=ROUTER64.to_bytes(8, "big"), command=b"SL")
        f = until(lambda f: f["id"] == "remote_at_response")
        assert f["parameter"] == ROUTER["SL"].to_bytes(4, "big") and f["status"] == b"\x00"
        zb.tx(frame_id=b"\x03", dest_addr_long=ROUTER64.to_bytes(8, "big"),
              dest_addr=b"\xff\xfe", data=b"\x7e\x7d\x11\x13")
        f = until(lambda f: f["id"] == "tx_status")
        assert f["deliver_status"] == b"\x00"
        zb.at(frame_id=b"\x04", command=b"NT", parameter=b"\x20")  # shortest discovery
        until(lambda f: f["id"] == "at_response" and f["frame_id"] == b"\x04")
        zb.at(frame_id=b"\x05", command=b"ND")
        f = until(lambda f: f["id"] == "at_response" and f["command"] == b"ND")
        assert f["parameter"]["node_identifier"] == b"SINS-ROUTER"
        assert f["parameter"]["source_addr"] == ROUTER["MY"].to_bytes(2, "big")
    assert len(frames) >= 30


def capture(args, n, deadline=DEADLINE):
    """Run a tool with a quiet, open stdin, take *n* bytes of its stdout, then stop it."""
    # own session: picocom signals its whole process group when it is told to quit
    proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True)
    out = b""
    try:
        end = time.monotonic() + deadline
        fd = proc.stdout.fileno()
        while len(out) < n and time.monotonic() < end:
            if select.select([fd], [], [], 1.0)[0]:
                chunk = os.read(fd, 65536)
                if not chunk:
                    break
                out += chunk
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=DEADLINE)
    assert len(out) >= n, err.decode(errors="replace")
    return out


@pytest.mark.skipif(shutil.which("socat") is None, reason="socat not installed")
def test_socat_reads_the_sins_port(lab):
    raw = capture(["socat", "-u", f"OPEN:{lab.ports['sins']},rawer", "STDOUT"], 3000)
    frames = [e for e in sins_decoder().decode(raw) if isinstance(e, Frame)]
    assert len(frames) >= 95


@pytest.mark.skipif(shutil.which("picocom") is None, reason="picocom not installed")
def test_picocom_reads_the_xbee_port(lab):
    raw = capture(["picocom", "-b", "115200", "-q", "--noreset", lab.ports["xbee"]], 4000)
    events = XBeeSinsChain(escaped=True).decode(raw)
    sins = [e for e in events if isinstance(e, Frame) and e.format == "sins"]
    assert len(sins) >= 50
    # only the cut ends of the capture may be incomplete
    assert sum(isinstance(e, DecodeError) and e.kind != "garbage" for e in events) <= 2


def test_nothing_a_client_does_kills_the_emulator(tmp_path):
    with emulate("office", speed="realtime", duration=60, record=tmp_path / "rec") as lab:
        hog = os.open(lab.ports["xbee"], os.O_RDWR | os.O_NOCTTY)  # opens, never reads
        try:
            for _ in range(30):  # open/close storm with garbage on every port
                for name in ("sins", "xbee", "nanoloc"):
                    fd = os.open(lab.ports[name], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
                    os.write(fd, os.urandom(200) + b"\x7e\x00\x04\x08\x01NI\x5f")
                    os.close(fd)
            # fill the hog's buffer: the coordinator sends about 4.7 kB/s; wait 6 s (240
            # nanoLOC reports) for 28 kB, more than the kernel keeps for a client (20 KiB)
            with serial.Serial(lab.ports["nanoloc"], 115200, timeout=1) as ser:
                read_frames(ser, nanoloc_decoder(), 240, deadline=60)
        finally:
            os.close(hog)
        with serial.Serial(lab.ports["sins"], 115200, timeout=1) as ser:  # still serving
            frames, _ = read_frames(ser, sins_decoder(), 20)
        assert len(frames) >= 20  # one read may finish several
        summary = lab.stop()
    assert summary["done"] and summary["interrupted"]
    assert summary["ports"]["xbee"]["dropped_overflow"] > 0
    assert summary["ports"]["xbee"]["received"] > 0
    # the recording has what the coordinator sent, whether or not anyone read it: the
    # answers to the NI queries of the storm (a query can be lost only if the random bytes
    # before it end in an escape that swallows its start)
    events = XBeeDecoder(escaped=True).decode(Recording(tmp_path / "rec").read_bytes("xbee"))
    answers = [e for e in events if isinstance(e, Frame) and e.type == 0x88
               and e.fields["command"] == b"NI"]
    assert 25 <= len(answers) <= 30
    assert all(a.fields["value"] == b"LAB-COORD" for a in answers)
