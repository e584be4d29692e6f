"""`navtwin decode` end to end: files, stdin, recordings, a live serial port, user errors."""
import json
import os
import select
import signal
import subprocess
import threading
import time

import pytest

from navtwin.protocols import recording, sins, xbee

from ..helpers import NAVTWIN, navtwin
from ..protocols.vectors import NANOLOC_5M, SINS_LEVEL, SINS_SEQ_WRAP


def decoded(*args, stdin=None):
    """``navtwin *args`` fed *stdin*: its exit code, its JSON lines, its stderr."""
    p = navtwin(*args, input=stdin, text=False)
    lines = [json.loads(x) for x in p.stdout.decode().splitlines()]
    return p.returncode, lines, p.stderr.decode()


def test_file_with_garbage(tmp_path):
    f = tmp_path / "s.bin"
    f.write_bytes(b"\x00\x01" + SINS_LEVEL + SINS_LEVEL[:-1] + b"\x00" + SINS_SEQ_WRAP)
    rc, lines, _ = decoded("decode", "--format", "sins", "--hex", str(f))
    assert rc == 0
    frames = [x for x in lines if "seq" in x]
    assert [x["seq"] for x in frames] == [1, 65535]
    assert frames[0]["offset"] == 2 and frames[0]["hex"] == SINS_LEVEL.hex().upper()
    assert frames[0]["accel_m_s2"][2] == pytest.approx(9.7952, abs=0.025)
    assert frames[1]["gyro_dps"][0] == pytest.approx(80.0, abs=0.04)
    errors = [x for x in lines if "error" in x]
    assert {"error": "bad_crc", "format": "sins", "offset": 32, "size": 30} in errors
    summary = lines[-1]["summary"]
    assert summary["frames"] == 2 and summary["errors"]["bad_crc"] >= 1
    assert summary["bytes"] == f.stat().st_size


def test_stdin_nanoloc():
    rc, lines, _ = decoded("decode", "--format", "nanoloc", "-", stdin=NANOLOC_5M * 2)
    assert rc == 0
    assert [x["distance_m"] for x in lines[:2]] == [pytest.approx(4.99994, abs=1e-5)] * 2
    assert lines[0]["complete"] is True and lines[-1]["summary"]["frames"] == 2


def test_recording_directory_xbee_sins(tmp_path):
    stream = SINS_LEVEL + SINS_SEQ_WRAP
    with recording.RecordingWriter(tmp_path / "rec", {"source": "test"}) as rec:
        port = rec.port("xbee")
        for i, cut in enumerate((0, 17, 45)):
            end = {0: 17, 17: 45, 45: 60}[cut]
            port.write(xbee.build(0x90, src64=0x0013A20040A1B2D4, src16=1, options=1,
                                  data=stream[cut:end]), t_device_ns=i * 10_000_000)
    rc, lines, _ = decoded("decode", "--format", "xbee-sins", str(tmp_path / "rec"))
    assert rc == 0
    assert [(x["seq"], x["source"]) for x in lines if "seq" in x] == \
           [(1, "0013A20040A1B2D4"), (65535, "0013A20040A1B2D4")]
    rc, lines, _ = decoded("decode", "--format", "xbee", "--api1", str(tmp_path / "rec"))
    assert rc == 0 and lines[-1]["summary"]["frames"] == 0  # API 2 bytes read as API 1: no frame


@pytest.mark.pty
def test_live_serial_port_follow():
    master, slave = os.openpty()
    import tty
    tty.setraw(slave)
    path = os.ttyname(slave)
    proc = subprocess.Popen([*NAVTWIN, "decode", "--format", "sins", "--follow", path],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    stop = threading.Event()

    def feed():  # the device keeps sending, as a real board would, until we have what we need
        k = 0
        while not stop.is_set():
            os.write(master, sins.build_sample(k, [0x8000] * 11))
            k += 1
            stop.wait(0.02)

    t = threading.Thread(target=feed, daemon=True)
    t.start()
    got, buf, deadline = [], b"", time.monotonic() + 30
    try:
        while len(got) < 5 and time.monotonic() < deadline:
            r, _, _ = select.select([proc.stdout], [], [], 1.0)
            if r:
                buf += os.read(proc.stdout.fileno(), 65536)
                *done, buf = buf.split(b"\n")
                got += [json.loads(x) for x in done if x]
    finally:
        stop.set()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        os.close(master)
        os.close(slave)
    assert len([x for x in got if "seq" in x]) >= 5
    seqs = [x["seq"] for x in got if "seq" in x]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # in order, none lost
    tail = [json.loads(x) for x in out.decode().splitlines() if x]
    assert proc.returncode == 0 and "summary" in tail[-1]


@pytest.mark.parametrize("args,needle", [
    (["decode", "--format", "sins", "/nonexistent/file"], "no such file"),
    (["decode", "--format", "gps", "-"], "invalid choice"),
    (["decode", "--format", "xbee", "--gyro-range", "200", "-"], "invalid choice"),
    (["bench", "nosuch"], "unknown benchmark"),
])
def test_user_errors_are_one_line(args, needle, tmp_path):
    rc, lines, err = decoded(*args, stdin=b"")
    assert rc == 2 and not lines
    assert len(err.strip().splitlines()) == 1 and needle in err


def test_not_a_recording(tmp_path):
    rc, _, err = decoded("decode", "--format", "sins", str(tmp_path))
    assert rc == 2 and "recording.json" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("fmt,api,build", [
    ("xbee", "--escaped", lambda k: xbee.build(0x8A, True, status=k)),
    ("xbee", "--api1", lambda k: xbee.build(0x8A, False, status=k)),
    ("sins", "--escaped", lambda k: sins.build_sample(k, [0x8000] * 11)),
])
def test_a_flood_of_7e_is_a_handful_of_lines_and_the_frames_after_it_decode(tmp_path, fmt, api,
                                                                          build):
    """Issue 7 point 9: 100 KB of 7E gave two JSON lines per byte."""
    f = tmp_path / "flood.bin"
    frames = [build(k) for k in range(5)]
    f.write_bytes(b"\x7e" * 100_000 + b"".join(frames))
    rc, lines, _ = decoded("decode", "--format", fmt, api, str(f))
    assert rc == 0 and len(lines) < 20
    got = [x for x in lines if "error" not in x and "summary" not in x]
    assert [x.get("status", x.get("seq")) for x in got] == list(range(5))
    errors = [x for x in lines if "error" in x]
    summary = lines[-1]["summary"]
    # every error still counted by kind: the lines' counts add up to the summary's
    for kind, n in summary["errors"].items():
        assert sum(x.get("count", 1) for x in errors if x["error"] == kind) == n
    garbage = [x for x in errors if x["error"] == "garbage"]
    assert sum(x["size"] for x in garbage) == summary["error_bytes"]["garbage"] == 100_000


def test_decode_prints_each_value_to_the_sensors_resolution_and_the_api_keeps_it_exact(tmp_path):
    from navtwin.protocols import adis16350
    from navtwin.protocols.decode import decode

    # 12 counts of 0.07326 deg/s is 0.8791200000000001 in binary floating point
    words = adis16350.sample_to_words(gyro_dps=(12 * 0.07326, -7 * 0.07326, 0.0),
                                      accel_g=(0.0, 3 * 2.522e-3, 1.0), temp_c=(25.1453, 25, 25))
    f = tmp_path / "s.bin"
    f.write_bytes(sins.build_sample(5, words))
    rc, lines, _ = decoded("decode", "--format", "sins", str(f))
    assert rc == 0
    printed = json.dumps(lines[0], separators=(",", ":"))
    assert '"gyro_dps":[0.87912,-0.51282,0.0]' in printed
    assert '"accel_g":[0.0,0.007566,1.001234]' in printed and '"temp_c":[25.1453,' in printed
    exact = next(decode(str(f), "sins"))
    assert exact["gyro_dps"][0] == 12 * 0.07326 != 0.87912  # only printing rounds
    for key in ("gyro_rad_s", "accel_m_s2", "supply_v"):
        assert lines[0][key] == pytest.approx(exact[key], abs=1e-5)
    (tmp_path / "n.bin").write_bytes(NANOLOC_5M)
    rc, lines, _ = decoded("decode", "--format", "nanoloc", str(tmp_path / "n.bin"))
    exact = next(decode(str(tmp_path / "n.bin"), "nanoloc"))["distance_m"]
    assert lines[0]["distance_m"] == round(exact, 5) != exact  # 1 ps is 0.07 mm
