"""Live control: a test breaks the running lab through its control socket (emulator.control),
from Python (emulator.api.Lab) or from ``navtwin ctl``."""
import errno
import json
import os
import select
import shutil
import socket
import stat
import subprocess
import time
from pathlib import Path

import pytest
import serial

from navtwin.emulator.api import emulate
from navtwin.emulator.control import Control, ControlError
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.protocols import nanoloc
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import nanoloc_decoder, sins_decoder

from ..helpers import navtwin

DEADLINE_S = 20.0


def _frames(decoder, chunks):
    out = []
    for c in chunks:
        out += [f for f in decoder.feed(c) if hasattr(f, "fields")]
    return out


def _read_frames(ser, decoder, want: int, deadline_s: float = DEADLINE_S):
    """Read until *want* frames decode (or the deadline); the frames."""
    frames, end = [], time.monotonic() + deadline_s
    while len(frames) < want and time.monotonic() < end:
        frames += [f for f in decoder.feed(ser.read(ser.in_waiting or 1)) if hasattr(f, "fields")]
    return frames


def test_the_socket_is_private_and_answers_status_and_refuses_bad_requests(tmp_path):
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        path = Path(lab.info["control"])
        assert path.parent == tmp_path / "links" and stat.S_IMODE(path.stat().st_mode) == 0o600
        st = lab.status()
        assert set(st["ports"]) == {"sins", "xbee", "nanoloc"}
        assert all(p["plugged"] for p in st["ports"].values()) and st["faults"] == []
        with pytest.raises(ControlError, match=r"unknown op 'explode'; use one of status"):
            lab.control.call("explode")
        with pytest.raises(ControlError, match=r"kind must be one of"):
            lab.fault("no_such_kind")
        with pytest.raises(ControlError, match=r"anchor 9 is not in \[\[anchors\]\]"):
            lab.fault("anchor_outage", anchor=9)
        with pytest.raises(ControlError, match=r"without start_s/end_s"):
            lab.control.call("fault", fault={"kind": "anchor_outage", "anchor": 1, "start_s": 1})
        with pytest.raises(ControlError, match=r"no port 'usb0'"):
            lab.unplug("usb0")
        # garbage on the socket: one error line, the connection and the lab carry on
        with socket.socket(socket.AF_UNIX) as s:
            s.settimeout(DEADLINE_S)
            s.connect(str(path))
            s.sendall(b"\xff\xfe not json\n{\"op\": \"status\"}\n")
            f = s.makefile()  # one reader: both replies may come in one segment
            replies = f.readline(), f.readline()
        assert json.loads(replies[0])["ok"] is False and "not JSON" in replies[0]
        assert json.loads(replies[1])["ok"] is True
        assert lab.status()["virtual_s"] > 0 and lab.running()


def test_unplug_hangs_up_the_client_and_replug_brings_the_port_back(tmp_path):
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        link = lab.ports["sins"]
        with serial.Serial(link, 115200, timeout=0.2) as ser:
            before = _read_frames(ser, sins_decoder(), 5)
            assert len(before) >= 5  # one read may decode more: the count is not the point
            assert lab.unplug("sins") == {"ok": True, "port": "sins", "plugged": False}
            assert not os.path.lexists(link)  # the device node is gone
            with pytest.raises(serial.SerialException):
                end = time.monotonic() + DEADLINE_S
                while time.monotonic() < end:  # what was in flight, then the hang-up
                    ser.read(4096)
        assert lab.status()["ports"]["sins"]["plugged"] is False
        reply = lab.replug("sins")
        assert os.readlink(link) == reply["pts"]
        with serial.Serial(link, 115200, timeout=0.2) as ser:
            frames = _read_frames(ser, sins_decoder(), 5)
            assert len(frames) >= 5  # valid SINS frames again, consecutive
            assert all(b.fields["seq"] == (a.fields["seq"] + 1) % 65536
                       for a, b in zip(frames, frames[1:]))
        # the board ran on while its cable was out: its counter went on (no wrap in 60 s)
        assert frames[0].fields["seq"] > before[-1].fields["seq"]
        summary = lab.stop()
    assert summary["ports"]["sins"]["unplugs"] == 1


def _hang_up(fd: int, deadline_s: float = DEADLINE_S) -> tuple:
    """What a non-blocking reader of *fd* sees when the line hangs up: the poll events, then
    what read and write give (reading what was in flight meanwhile)."""
    p = select.poll()
    p.register(fd, select.POLLIN)
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        events = dict(p.poll(100)).get(fd, 0)
        if events & (select.POLLHUP | select.POLLERR):
            break
        try:
            os.read(fd, 65536)
        except BlockingIOError:
            pass
    try:
        got = os.read(fd, 65536)
    except OSError as e:
        got = errno.errorcode[e.errno]
    try:
        wrote = os.write(fd, b"x")
    except OSError as e:
        wrote = errno.errorcode[e.errno]
    return events, got, wrote


def test_unplug_hangs_readers_up_exactly_as_a_bare_pty_whose_master_closes(tmp_path):
    master, slave = os.openpty()
    fd = os.open(os.ttyname(slave), os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    os.close(slave)
    os.close(master)
    bare = _hang_up(fd)
    os.close(fd)
    assert bare[0] & select.POLLHUP and bare[1:] == (b"", "EIO")  # as usb_serial_disconnect
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        fd = os.open(lab.ports["sins"], os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            assert select.select([fd], [], [], DEADLINE_S)[0]  # the board's frames flow
            lab.unplug("sins")
            assert _hang_up(fd) == bare
        finally:
            os.close(fd)


def _node_serialport() -> bool:
    node = shutil.which("node")
    return node is not None and subprocess.run(
        [node, "-e", "require('serialport')"], capture_output=True).returncode == 0


@pytest.mark.skipif(not _node_serialport(),
                    reason="node serialport not installed (npm install serialport; NODE_PATH)")
def test_node_serialport_sees_close_on_every_unplug(tmp_path):
    """A reader caught between reads at the hang-up reads 0 bytes forever and never closes:
    the line goes quiet first, so node is back in poll and sees POLLERR."""
    script = Path(__file__).with_name("serialport_reader.js")
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        for k in range(5):
            node = subprocess.Popen(["node", str(script), lab.ports["sins"]],
                                    stdout=subprocess.PIPE)
            try:
                lines = []

                def until(word: str) -> bool:  # unbuffered: a line may come with the next
                    end = time.monotonic() + DEADLINE_S
                    while word not in lines and time.monotonic() < end:
                        if select.select([node.stdout], [], [], 0.1)[0]:
                            lines.extend(os.read(node.stdout.fileno(), 4096).decode().split())
                    return word in lines

                assert until("data"), f"open {k}: {lines}"
                lab.unplug("sins")
                assert until("close"), f"unplug {k}: {lines}"
            finally:
                node.kill()
                node.wait()
            lab.replug("sins")


def test_a_live_anchor_outage_times_out_that_anchor_and_nothing_else(tmp_path):
    sc = load_scenario("office")
    rec = tmp_path / "rec"
    with emulate("office", duration=9, link_dir=tmp_path / "links", record=rec) as lab:
        fault = lab.fault("anchor_outage", 2.0, anchor=1)
        assert fault["kind"] == "anchor_outage" and fault["end_s"] == pytest.approx(fault["start_s"] + 2)
        assert [f["id"] for f in lab.status()["faults"]] == [fault["id"]]
        lab.wait_done(60)
    # the same run without the fault, at max speed, in process
    clean: list = []
    with Emulation(sc, None, speed=None, duration_s=9, ports=False,
                   sink=lambda c: clean.append(c.data) if c.port == "nanoloc" else None) as emu:
        emu.run()
    got = _frames(nanoloc_decoder(), [c.data for c in Recording(rec).chunks("nanoloc")])
    want = _frames(nanoloc_decoder(), clean)
    assert len(got) == len(want) > 300
    changed = 0
    for g, w in zip(got, want):
        g, w = g.fields, w.fields
        assert (g["seq"], g["anchor"], g["t_us"]) == (w["seq"], w["anchor"], w["t_us"])
        # the exchange starts a few ms before its t_us: a margin of one cycle either side
        inside = fault["start_s"] + 0.1 <= g["t_us"] / 1e6 < fault["end_s"] - 0.1
        near = fault["start_s"] - 0.1 <= g["t_us"] / 1e6 < fault["end_s"] + 0.1
        if g["anchor"] == 1 and inside:
            assert g["status"] == nanoloc.STATUS_TIMEOUT
            changed += w["status"] != nanoloc.STATUS_TIMEOUT
        elif not (g["anchor"] == 1 and near):
            assert g == w
    assert changed > 10  # about 2 s of anchor 1's exchanges


def test_navtwin_ctl_prints_replies_and_refuses_in_one_line(tmp_path):
    def ctl(*args):
        return navtwin("ctl", "--link-dir", tmp_path / "links", *args)

    r = ctl("status")
    assert r.returncode == 2 and "cannot connect" in r.stderr and len(r.stderr.splitlines()) == 1
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        r = ctl("fault", "anchor_outage:anchor=2", "--duration", "30")
        assert r.returncode == 0, r.stderr
        fid = json.loads(r.stdout)["id"]
        assert [f["id"] for f in json.loads(ctl("status").stdout)["faults"]] == [fid]
        r = ctl("fault", "anchor_outage:anchor=2,colour=blue")
        assert r.returncode == 2 and "unknown key 'colour'" in r.stderr
        assert "Traceback" not in r.stderr and len(r.stderr.splitlines()) == 1
        assert json.loads(ctl("clear", str(fid)).stdout)["cleared"] == [fid]
        assert ctl("unplug", "nanoloc").returncode == 0
        assert not os.path.lexists(lab.ports["nanoloc"])
        assert ctl("replug", "nanoloc").returncode == 0 and os.path.lexists(lab.ports["nanoloc"])


def test_reset_power_cycles_the_board_under_a_reading_client(tmp_path):
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        with serial.Serial(lab.ports["sins"], 115200, timeout=0.2) as ser:
            dec = sins_decoder()
            assert len(_read_frames(ser, dec, 3)) >= 3  # one read may hold more
            reply = lab.reset("board", 0.3)
            assert reply["kind"] == "board_reset"
            end = time.monotonic() + DEADLINE_S
            seqs = []
            while time.monotonic() < end and 0 not in seqs:
                seqs += [f.fields["seq"] for f in _read_frames(ser, dec, 1, 1.0)]
            assert 0 in seqs  # the board came back and counts from power-up
        with pytest.raises(ControlError, match=r"no device 'toaster'"):
            lab.control.call("reset", device="toaster")


def test_reset_and_faults_address_one_car(tmp_path):
    """In a three-car lab, `ctl reset board --vehicle 2` power-cycles car 2's board only: its
    port's counter starts again while car 1's runs on; a car the lab lacks is refused."""
    with emulate("office-convoy", duration=60, link_dir=tmp_path / "links") as lab:
        with serial.Serial(lab.ports["sins2"], 115200, timeout=0.2) as two, \
                serial.Serial(lab.ports["sins"], 115200, timeout=0.2) as one:
            d2, d1 = sins_decoder(), sins_decoder()
            assert len(_read_frames(two, d2, 3)) >= 3
            r = navtwin("ctl", "--link-dir", tmp_path / "links", "reset", "board", "--vehicle", "2",
                        "--duration", "0.3")
            assert r.returncode == 0 and json.loads(r.stdout)["kind"] == "board_reset", r.stderr
            end = time.monotonic() + DEADLINE_S
            seqs = []
            while time.monotonic() < end and 0 not in seqs:
                seqs += [f.fields["seq"] for f in _read_frames(two, d2, 1, 1.0)]
            assert 0 in seqs  # car 2's board came back
            one.reset_input_buffer()
            first = [f.fields["seq"] for f in _read_frames(one, sins_decoder(), 20)]
            # car 1's board never stopped: it counts on from before car 2's power-cycle, which
            # took 0.3 s (30 frames) after car 2's board had counted up to seqs[0]
            assert min(first) > max(seqs[0], 30) and first == sorted(first)
        with pytest.raises(ControlError, match=r"vehicle 4: the scenario has vehicles 1 to 3"):
            lab.reset("board", vehicle=4)
        with pytest.raises(ControlError, match=r"the vehicles share one coordinator"):
            lab.reset("coordinator", vehicle=2)


def test_a_live_line_fault_garbles_the_port_until_cleared_and_the_ledger_has_it(tmp_path):
    rec = tmp_path / "rec"
    with emulate("office", duration=60, link_dir=tmp_path / "links", record=rec) as lab:
        with serial.Serial(lab.ports["sins"], 115200, timeout=0.2) as ser:
            dec = sins_decoder()
            assert len(_read_frames(ser, dec, 5)) >= 5
            lab.fault("bit_errors", port="sins", ber=0.01)  # ~2 flipped bits per frame
            end = time.monotonic() + DEADLINE_S
            while time.monotonic() < end and not sum(dec.errors.values()):
                dec.feed(ser.read(ser.in_waiting or 1))
            assert sum(dec.errors.values()) > 0  # the client's decoder sees the damage
            lab.clear()
            ser.reset_input_buffer()
            fresh = sins_decoder()
            frames = _read_frames(ser, fresh, 20)
            assert len(frames) >= 20  # clean again
        lab.stop()
    ledger = Recording(rec).faults()
    assert ledger and {e["kind"] for e in ledger} == {"bit_errors"}
    assert all(e["port"] == "sins" and e["fault"] is None for e in ledger)


def test_a_live_fault_that_has_ended_is_no_longer_listed(tmp_path):
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        short = lab.fault("bit_errors", 0.3, port="sins", ber=1e-4)
        long = lab.fault("bit_errors", port="nanoloc", ber=1e-4)  # until cleared
        end = time.monotonic() + DEADLINE_S
        while (st := lab.status())["virtual_s"] <= short["end_s"]:
            assert time.monotonic() < end, "the emulator's time did not pass the fault's end"
            time.sleep(0.05)
        assert [f["id"] for f in st["faults"]] == [long["id"]]
        with pytest.raises(ControlError, match="no live fault"):
            lab.clear(short["id"])
        assert lab.clear()["cleared"] == [long["id"]]
        lab.stop()
