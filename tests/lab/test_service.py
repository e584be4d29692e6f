"""The live service on real PTYs and sockets: recording, replay equality, reconnects.

Every wait is a condition polled against a generous deadline (the box is loaded); the
feeder paces its writes like the devices would, which no assertion depends on.
"""
import io
import json
import math
import os
import select
import socket
import threading
import time

import pytest

from navtwin.host.output import estimate_line
from navtwin.host.replay import replay
from navtwin.host.service import TX_PORT, Service
from navtwin.host.tracks import DEFAULT
from navtwin.protocols import adis16350, sins
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import XBeeDecoder

from ..helpers import OFFICE
from ..host.fake_estimator import RecordingEstimator
from . import lab_bytes

pytestmark = pytest.mark.pty

DEADLINE_S = 60.0


def wait_for(cond, what: str, timeout: float = DEADLINE_S) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.005)


def pty_pair():
    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)  # the host opens the slave by its path, like the emulator's clients
    return master, path


class Running:
    """A Service on its own thread; stop() ends it and returns its summary."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.summary = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        self.summary = self.service.run(self._stop)

    def stop(self) -> dict:
        self._stop.set()
        self._thread.join(DEADLINE_S)
        assert not self._thread.is_alive(), "service did not stop"
        return self.summary


def paced_write(chunks, masters: dict[str, int]) -> dict[str, int]:
    """Write (port, bytes, ns) at their times from now; bytes written per port."""
    total = dict.fromkeys(masters, 0)
    t0 = time.monotonic_ns()
    for port, data, t_ns in chunks:
        delay = (t0 + t_ns - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)
        os.write(masters[port], data)
        total[port] += len(data)
    return total


def test_live_run_over_ptys_then_replay_gives_the_same_bytes(tmp_path):
    pairs = {p: pty_pair() for p in ("xbee", "nanoloc")}
    out, status = io.StringIO(), io.StringIO()
    svc = Service({p: path for p, (_, path) in pairs.items()}, OFFICE, DEFAULT,
                  out=out, record=tmp_path / "rec", status=status, status_period_s=0.5)
    run = Running(svc)
    wait_for(svc.started.is_set, "the service to open its ports")
    total = paced_write(lab_bytes.office(3.0, 21),
                        {p: m for p, (m, _) in pairs.items()})
    wait_for(lambda: svc.bytes == total, "the service to process every byte")
    summary = run.stop()
    live = out.getvalue()
    assert {json.loads(x)["filter"] for x in live.splitlines()} == set(DEFAULT)
    assert summary["counts"]["imu"] == 300 and summary["counts"]["reports"] == 120
    got = []
    replay(Recording(tmp_path / "rec"), lambda es: got.extend(map(estimate_line, es)))
    assert "".join(got) == live
    # the host asked the coordinator for DB and AP once (at the first chunk), and recorded it
    rec = Recording(tmp_path / "rec")
    # host time 0 on CLOCK_MONOTONIC, as the summary gives it: reads go on the emulator's clock
    assert rec.meta["t0_monotonic_ns"] == summary["t0_monotonic_ns"] > 0
    sent = XBeeDecoder(escaped=True).decode(rec.read_bytes(TX_PORT))
    assert [(f.type, f.fields["command"]) for f in sent] == [(0x08, b"DB"), (0x08, b"AP")]
    assert select.select([pairs["xbee"][0]], [], [], DEADLINE_S)[0], "nothing sent"
    received = os.read(pairs["xbee"][0], 1024)
    assert received == rec.read_bytes(TX_PORT)
    # periodic status lines on stderr with rates per port and latency
    lines = [json.loads(x) for x in status.getvalue().splitlines()]
    periodic = [x["status"] for x in lines if "status" in x and "t_s" in x["status"]]
    assert periodic and set(periodic[-1]["ports"]) == {"xbee", "nanoloc"}
    assert "latency" in periodic[-1] and "summary" in lines[-1]
    for m, _ in pairs.values():
        os.close(m)


def _frames(seqs) -> list[bytes]:
    """SINS frames whose x gyro reads the sequence number in LSB (to find them again)."""
    lsb = adis16350.GYRO_LSB_DPS[300]
    return [sins.build_sample(s, adis16350.sample_to_words(gyro_dps=((s % 1000) * lsb, 0, 0),
                                                           accel_g=(0, 0, 1))) for s in seqs]


def _seqs(est) -> list[int]:
    lsb = adis16350.GYRO_LSB_DPS[300]
    return [round(math.degrees(c[2][0]) / lsb) for c in est.calls if c[0] == "imu"]


def _check_continuous(est, n):
    imu = [c for c in est.calls if c[0] == "imu"]
    assert len(imu) == n
    assert all(b[1] > a[1] for a, b in zip(imu, imu[1:]))


def test_a_pty_that_goes_away_and_comes_back_is_reopened(tmp_path):
    links = tmp_path / "links"
    links.mkdir(mode=0o700)
    link = links / "sins"
    m1, p1 = pty_pair()
    os.symlink(p1, link)
    est, status = RecordingEstimator(), io.StringIO()
    svc = Service({"sins": str(link)}, OFFICE, ("kf",), out=io.StringIO(), make_estimator=lambda _: est,
                  status=status)
    run = Running(svc)
    wait_for(svc.started.is_set, "the service to open its port")
    frames = _frames(range(65_500, 65_500 + 200))  # the board's counter wraps in between
    sent = 0
    for f in frames[:100]:
        os.write(m1, f)
        sent += len(f)
        time.sleep(0.001)
    wait_for(lambda: svc.bytes["sins"] == sent, "the first 100 frames")
    os.close(m1)  # the device is gone: the host's read fails (EIO)
    os.unlink(link)
    reader = svc._readers["sins"]
    wait_for(lambda: reader.state == "down", "the host to notice the port is gone")
    m2, p2 = pty_pair()
    os.symlink(p2, link)
    wait_for(lambda: reader.state == "open", "the host to reopen the port")
    for f in frames[100:]:
        os.write(m2, f)
        sent += len(f)
        time.sleep(0.001)
    wait_for(lambda: svc.bytes["sins"] == sent, "the last 100 frames")
    summary = run.stop()
    os.close(m2)
    _check_continuous(est, 200)  # the estimator kept its state: one stream, in order
    assert _seqs(est) == [s % 1000 for s in range(65_500, 65_700)]
    assert summary["reconnects"] == {"sins": 1} and summary["vehicles"][0]["imu_clock"]["restarts"] == 0
    events = [json.loads(x)["status"].get("event") for x in status.getvalue().splitlines()
              if "status" in json.loads(x)]
    assert "port_down" in events and events.index("port_up") > events.index("port_down")


def test_a_socket_port_that_closes_and_reopens_is_reconnected():
    # pyserial drops what is waiting when it opens a socket, so the server streams each part
    # only once the host has the port open (else a starved host loses a part to that flush);
    # it goes away after the first part, mid-stream
    frames = _frames(range(300))
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    stop_serving = threading.Event()
    est = RecordingEstimator()
    svc = Service({"sins": f"socket://127.0.0.1:{port}"}, OFFICE, ("kf",), out=io.StringIO(),
                  make_estimator=lambda _: est)

    def serve():
        for k, part in enumerate((frames[:150], frames[150:])):
            conn, _ = server.accept()
            if k == 0:
                wait_for(svc.started.is_set, "the service to open its port")
            else:  # the host saw the first connection end, and has opened the port again
                wait_for(lambda: svc._readers["sins"].reconnects == 1
                         and svc._readers["sins"].state == "open", "the host to reconnect")
            for f in part:
                conn.sendall(f)
                time.sleep(0.002)
            if k == 1:
                stop_serving.wait(DEADLINE_S)
            conn.close()

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    run = Running(svc)
    wait_for(lambda: 299 in _seqs(est), "the last frame")
    summary = run.stop()
    stop_serving.set()
    th.join(DEADLINE_S)
    server.close()
    assert _seqs(est) == list(range(300))  # nothing lost: each part came after an open
    _check_continuous(est, 300)
    assert summary["reconnects"] == {"sins": 1} and summary["vehicles"][0]["imu_clock"]["restarts"] == 0
