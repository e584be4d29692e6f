"""The control socket holds up under what clients send: every request gets an answer, nothing
a client sends stops the lab, idle connections time out and a full house answers "busy"."""
import json
import socket
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from navtwin.emulator.api import emulate
from navtwin.emulator.control import MAX_CLIENTS, MAX_LINE, OPS, ControlServer
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario

from ..helpers import navtwin

DEADLINE_S = 20.0

#: requests that each stopped the lab once (TypeError, RecursionError in a handler), and
#: values that passed the checks but could not be applied
MALFORMED = [
    b'{"op":"clear","id":[1]}',
    b'{"op":"unplug","port":[1]}',
    b'{"op":"replug","port":{"a":1}}',
    b'{"op":"reset","device":{}}',
    b'{"op":"reset","device":"board","duration_s":NaN}',
    b'{"op":"fault","fault":{"kind":[1]}}',
    b'{"op":"fault","fault":{"kind":{"a":[]}}}',
    b'{"op":"fault","fault":[]}',
    b'{"op":"fault","fault":{"kind":"bit_errors","port":"sins","ber":' + b"[" * 900
    + b"]" * 900 + b"}}",
    b'{"op":"fault","fault":{"kind":"bandwidth","port":"sins","bytes_per_s":1e-300}}',
    b'{"op":"fault","fault":{"kind":"garbage","port":"sins","rate_hz":1e-300}}',
    # parts the scenario lacks: the scenario's own rule (a board_reset on vehicle 7 was "ok")
    b'{"op":"fault","fault":{"kind":"board_reset","vehicle":7},"duration_s":1}',
    b'{"op":"fault","fault":{"kind":"anchor_outage","anchor":9},"duration_s":1}',
    b'{"op":"clear","id":' + b"9" * 4000 + b"}",
    b'{"op":"clear","id":' + b"9" * 5000 + b"}",
    b'{"op":"status","colour":"blue"}',
    b'{"op":"status","' + b"k" * 60000 + b'":1}',
    b'{"op":["status"]}',
    b"[" * 60000,
    b"\xff\xfe",
    b"[]",
    b"7",
]


def _replies(sock, n: int) -> list[dict]:
    """*n* reply lines from *sock* (its timeout bounds each read)."""
    f = sock.makefile("rb")
    return [json.loads(f.readline()) for _ in range(n)]


def test_every_malformed_request_is_answered_and_the_lab_runs_on(tmp_path):
    with emulate("office", duration=60, link_dir=tmp_path / "links") as lab:
        with socket.socket(socket.AF_UNIX) as s:
            s.settimeout(DEADLINE_S)
            s.connect(lab.info["control"])
            for request in MALFORMED:
                assert len(request) < MAX_LINE
                s.sendall(request + b"\n")
                reply, = _replies(s, 1)
                assert reply["ok"] is False, (request[:80], reply)
                assert reply["error"] and "\n" not in reply["error"]
                assert len(reply["error"]) < 1000, reply["error"][:200]
            s.sendall(b'{"op":"status"}\n')
            assert _replies(s, 1)[0]["ok"] is True
        assert lab.running() and lab.status()["faults"] == []  # nothing was applied
        st_ = lab.status()
        assert all(p["plugged"] for p in st_["ports"].values())
        summary = lab.stop()
    assert summary["interrupted"]  # stopped by us, not by a request


def test_a_full_house_answers_busy_and_navtwin_ctl_says_so(tmp_path):
    def ctl(*args):
        return navtwin("ctl", "--link-dir", tmp_path / "links", *args)

    with emulate("office", duration=70, link_dir=tmp_path / "links") as lab:
        clients = []
        try:
            for _ in range(MAX_CLIENTS):  # each answered once: the lab has taken it in
                s = socket.socket(socket.AF_UNIX)
                clients.append(s)
                s.settimeout(DEADLINE_S)
                s.connect(lab.info["control"])
                s.sendall(b'{"op":"status"}\n')
                assert _replies(s, 1)[0]["ok"] is True
            r = ctl("status")
            assert r.returncode == 2 and r.stdout == ""
            assert "Traceback" not in r.stderr and len(r.stderr.splitlines()) == 1
            assert "busy" in r.stderr and "stopped" not in r.stderr, r.stderr
            clients.pop().close()  # a place frees up
            end = time.monotonic() + DEADLINE_S
            while (r := ctl("status")).returncode != 0:  # until the lab saw the close
                assert "busy" in r.stderr and time.monotonic() < end, r.stderr
            assert json.loads(r.stdout)["ok"] is True
        finally:
            for s in clients:
                s.close()
        assert lab.running()


def _server(tmp_path, idle_timeout_s: float) -> ControlServer:
    return ControlServer(tmp_path / "control", lambda op, args: {"op": op},
                         idle_timeout_s=idle_timeout_s)


def _serve_until(server: ControlServer, done) -> None:
    end = time.monotonic() + DEADLINE_S
    while not done():
        assert time.monotonic() < end, "the server did not get there in time"
        server.serve()
        time.sleep(0.01)


def _closed(sock) -> bool:
    """Whether the server closed *sock* (which has nothing to read before; no timeout set,
    or Python waits for it before a MSG_DONTWAIT read)."""
    try:
        return sock.recv(4096, socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False


def _readable(sock) -> bool:
    try:
        sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT)
    except BlockingIOError:
        return False
    return True


def test_idle_connections_time_out_and_free_their_place(tmp_path):
    server = _server(tmp_path, idle_timeout_s=0.3)
    try:
        idle, trickling = socket.socket(socket.AF_UNIX), socket.socket(socket.AF_UNIX)
        for s in (idle, trickling):
            s.connect(str(server.path))
        trickling.sendall(b'{"op": ')  # bytes, but never a whole request
        _serve_until(server, lambda: _closed(idle) and _closed(trickling))
        assert server.fds() == [server.sock]
        # a client that asks within the timeout is answered
        with socket.socket(socket.AF_UNIX) as s:
            s.settimeout(DEADLINE_S)
            s.connect(str(server.path))
            s.sendall(b'{"op": "status"}\n')
            _serve_until(server, lambda: len(server.fds()) == 2 and server.requests == 1)
            assert _replies(s, 1) == [{"ok": True, "op": "status"}]
    finally:
        server.close()


def test_a_client_beyond_the_full_house_is_told_busy(tmp_path):
    server = _server(tmp_path, idle_timeout_s=600)
    clients = [socket.socket(socket.AF_UNIX) for _ in range(MAX_CLIENTS + 1)]
    try:
        for s in clients[:-1]:
            s.connect(str(server.path))
        _serve_until(server, lambda: len(server.fds()) == MAX_CLIENTS + 1)
        late = clients[-1]
        late.connect(str(server.path))
        _serve_until(server, lambda: _readable(late))
        late.settimeout(DEADLINE_S)
        reply, = _replies(late, 1)
        assert reply["ok"] is False and reply["error"].startswith("busy")
        assert len(server.fds()) == MAX_CLIENTS + 1  # the others keep their places
    finally:
        for s in clients:
            s.close()
        server.close()


@pytest.fixture(scope="module")
def emulation(tmp_path_factory):
    """A lab in this process, its loop not running: requests are done as it would do them."""
    with Emulation(load_scenario("office"), speed=None, duration_s=5,
                   link_dir=tmp_path_factory.mktemp("links") / "l") as emu:
        yield emu


# any JSON, with the keys and values requests use more often than chance would
NAMES = st.sampled_from(["op", "fault", "id", "port", "device", "duration_s", "kind", "ber",
                         "start_s", "end_s", "anchor", "bytes_per_s", "x"])
SCALARS = (st.none() | st.booleans() | st.integers() | st.floats()
           | st.sampled_from([*OPS, "sins", "board", "bit_errors", "anchor_outage", ""])
           | st.text(max_size=8))
JSON = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(NAMES | st.text(max_size=4), inner, max_size=5),
                    max_leaves=20)
REQUESTS = st.fixed_dictionaries({"op": st.sampled_from(list(OPS)) | JSON},
                                 optional={n: JSON for n in ["fault", "id", "port", "device",
                                                             "duration_s"]})


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(REQUESTS, JSON))
def test_any_json_request_gets_one_reply_from_a_lab(emulation, req):
    reply = emulation.control._reply(json.dumps(req).encode())
    assert isinstance(reply["ok"], bool)
    assert reply["ok"] or ("\n" not in reply["error"] and reply["error"])
