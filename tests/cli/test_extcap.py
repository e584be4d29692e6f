"""``navtwin extcap``: Wireshark's extcap protocol (interfaces, dlts, config) and a live capture
of a running lab, read back as pcapng and by tshark: one interface per port, the recording's
chunks as packets."""
import os
import re
import signal
import struct
import subprocess
import time

import pytest

from navtwin.emulator.api import emulate
from navtwin.protocols import ports
from navtwin.protocols.capture import linktype
from navtwin.protocols.linkdir import default_link_dir
from navtwin.protocols.pcapng import INBOUND
from navtwin.protocols.recording import Recording

from ..helpers import NAVTWIN, navtwin
from ..tshark import needs_tshark, tshark

DEADLINE_S = 30.0
SENTENCE = re.compile(r"^(\w+) ((?:\{[^{}=]+=[^{}]*\})+)$")


def sentences(text: str) -> list[tuple[str, dict]]:
    """The extcap protocol's lines: ``kind {key=value}...`` -> (kind, {key: value})."""
    out = []
    for line in text.splitlines():
        m = SENTENCE.match(line)
        assert m, f"not an extcap sentence: {line!r}"
        out.append((m[1], dict(re.findall(r"\{([^{}=]+)=([^{}]*)\}", m[2]))))
    return out


def test_interfaces_dlts_and_config_follow_the_extcap_protocol():
    listed = sentences(navtwin("extcap", "--extcap-interfaces", "--extcap-version=4.0").stdout)
    assert [k for k, _ in listed] == ["extcap", "interface"]
    assert listed[0][1]["version"]
    assert listed[1][1]["value"] == "navtwin"
    assert sentences(navtwin("extcap", "--extcap-version").stdout) == listed[:1]
    (kind, dlt), = sentences(navtwin("extcap", "--extcap-dlts", "--extcap-interface",
                                     "navtwin").stdout)
    first = ports.listed()[0].name
    assert kind == "dlt" and int(dlt["number"]) == linktype(first, {})
    (kind, arg), = sentences(navtwin("extcap", "--extcap-config", "--extcap-interface",
                                     "navtwin").stdout)
    assert kind == "arg" and arg["call"] == "--link-dir" and arg["type"] == "string"
    assert arg["default"] == str(default_link_dir())


@pytest.mark.parametrize("args, says", [
    (["--extcap-dlts", "--extcap-interface", "eth0"], "--extcap-interface 'eth0' is not an "
                                                       "interface of navtwin; use navtwin"),
    (["--capture", "--extcap-interface", "navtwin", "--fifo", "{tmp}/out", "--link-dir",
      "{tmp}"], "--link-dir {tmp}/tap: cannot connect (no such socket); is an emulator "
                "running on this link directory?"),
    (["--capture", "--extcap-interface", "navtwin"], "--capture needs --fifo PATH"),
])
def test_bad_requests_are_one_line_and_status_2(tmp_path, args, says):
    done = navtwin("extcap", *[a.format(tmp=tmp_path) for a in args])
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and says.format(tmp=tmp_path) in done.stderr
    assert not (tmp_path / "out").exists()  # no lab: the FIFO is never opened


def read_pcapng(data: bytes) -> tuple[list[tuple[str, int]], list[tuple[int, int, int, bytes]]]:
    """(interfaces as (name, link type), packets as (interface, t_ns, flags, data)) of a
    little-endian pcapng stream as navtwin writes it."""
    interfaces, packets, at = [], [], 0
    while at < len(data):
        kind, size = struct.unpack_from("<II", data, at)
        body = data[at + 8:at + size - 4]
        if kind == 1:
            link, = struct.unpack_from("<H", body)
            options = _options(body[8:])
            interfaces.append((options[2].decode(), link))
        elif kind == 6:
            iface, hi, lo, caplen, _ = struct.unpack_from("<IIIII", body)
            options = _options(body[20 + caplen + (-caplen % 4):])
            flags = struct.unpack("<I", options[2])[0] if 2 in options else 0
            packets.append((iface, hi << 32 | lo, flags, body[20:20 + caplen]))
        at += size
    return interfaces, packets


def _options(raw: bytes) -> dict[int, bytes]:
    out, at = {}, 0
    while at + 4 <= len(raw):
        code, size = struct.unpack_from("<HH", raw, at)
        if code == 0:
            break
        out[code] = raw[at + 4:at + 4 + size]
        at += 4 + size + (-size % 4)
    return out


def assert_capture_is_the_recording(data: bytes, rec: Recording,
                                    to_end: bool = False) -> dict[str, int]:
    """Each port's (and the air's) packets are its recorded chunks from the one the capture
    started at (by device time), up to the recording's end if *to_end*: the same bytes,
    device times and direction; the packets per interface."""
    interfaces, packets = read_pcapng(data)
    assert sorted(interfaces) == sorted(
        [(p, linktype(p, s)) for p, s in rec.meta["ports"].items()]
        + [(name, s.linktype) for name, s in rec.streams.items()])  # the air too
    counts = {}
    for i, (port, _) in enumerate(interfaces):
        mine = [p for p in packets if p[0] == i]
        assert mine, f"no packets of {port}"
        chunks = list(rec.chunks(port))
        first = next(n for n, c in enumerate(chunks) if c.t_device_ns == mine[0][1])
        tail = chunks[first:] if to_end else chunks[first:first + len(mine)]
        assert [(p[1], p[3]) for p in mine] == [(c.t_device_ns, c.data) for c in tail]
        assert {p[2] for p in mine} == {0 if port in rec.streams else INBOUND}  # the air: none
        counts[port] = len(mine)
    return counts


def test_a_capture_into_a_file_is_the_recording_and_ends_with_the_lab(tmp_path):
    out = tmp_path / "live.pcapng"
    with emulate("office", seed=5, duration=5, record=tmp_path / "rec") as lab:
        done = navtwin("extcap", "--capture", "--extcap-interface", "navtwin", "--fifo", out,
                       "--link-dir", lab.info["link_dir"], timeout=DEADLINE_S)
        lab.wait_done(DEADLINE_S)
    assert done.returncode == 0, done.stderr
    rec = Recording(tmp_path / "rec")
    # it ended with the run: every chunk from its first to the recording's last
    counts = assert_capture_is_the_recording(out.read_bytes(), rec, to_end=True)
    tshark()  # Wireshark reads it: the same packets on the same interfaces
    assert _tshark_counts(out) == counts


def test_the_capture_filter_keeps_the_ports_it_names(tmp_path):
    out = tmp_path / "live.pcapng"
    with emulate("office", seed=5, duration=2) as lab:
        bad = navtwin("extcap", "--capture", "--fifo", tmp_path / "no", "--link-dir",
                      lab.info["link_dir"], "--extcap-capture-filter", "sins,gps")
        done = navtwin("extcap", "--capture", "--extcap-interface", "navtwin", "--fifo", out,
                       "--link-dir", lab.info["link_dir"], "--extcap-capture-filter", "sins",
                       timeout=DEADLINE_S)
        lab.wait_done(DEADLINE_S)  # it ended the capture
    assert done.returncode == 0, done.stderr
    interfaces, packets = read_pcapng(out.read_bytes())
    assert [name for name, _ in interfaces] == ["sins"] and packets
    assert bad.returncode == 2 and "no port or stream gps in this lab" in bad.stderr
    assert not (tmp_path / "no").exists()


def _tshark_counts(path) -> dict[str, int]:
    fields = subprocess.run(["tshark", "-r", str(path), "-T", "fields", "-e",
                             "frame.interface_name"], capture_output=True, text=True,
                            timeout=DEADLINE_S, check=True).stdout.split()
    return {name: fields.count(name) for name in set(fields)}


@needs_tshark
def test_sigterm_ends_a_capture_cleanly(tmp_path):
    out = tmp_path / "live.pcapng"
    with emulate("office", seed=5, duration=60) as lab:
        proc = subprocess.Popen([*NAVTWIN, "extcap", "--capture", "--extcap-interface",
                                 "navtwin", "--fifo", str(out), "--link-dir",
                                 lab.info["link_dir"]], stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + DEADLINE_S
        while not (out.exists() and out.stat().st_size > 4096):  # some packets are in
            assert time.monotonic() < deadline and proc.poll() is None, "no packets came"
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=DEADLINE_S)
        assert proc.returncode == 0 and err == ""
        assert lab.running()
    assert sum(_tshark_counts(out).values()) > 0


@needs_tshark
def test_a_fifo_reader_that_stops_ends_the_capture(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with emulate("office", seed=5, duration=60) as lab:
        reader = subprocess.Popen(["tshark", "-r", str(fifo), "-c", "20", "-T", "fields", "-e",
                                   "frame.interface_name"], stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True)
        done = navtwin("extcap", "--capture", "--extcap-interface", "navtwin", "--fifo", fifo,
                       "--link-dir", lab.info["link_dir"], timeout=DEADLINE_S)
        names, _ = reader.communicate(timeout=DEADLINE_S)
        assert lab.running()
    assert done.returncode == 0 and done.stderr == ""
    assert len(names.split()) == 20 and set(names.split()) <= {*ports.names(), "air"}


@needs_tshark
def test_tshark_captures_a_running_lab_through_the_installed_extcap(tmp_path):
    env = {**os.environ, "HOME": str(tmp_path / "home")}
    env.pop("XDG_CONFIG_HOME", None)
    installed = navtwin("extcap", "--install", env=env)
    assert installed.returncode == 0, installed.stderr
    wrapper = re.search(r"installed (\S+);", installed.stdout)[1]
    assert wrapper.startswith(str(tmp_path / "home")) and os.access(wrapper, os.X_OK)
    listed = subprocess.run(["tshark", "-D"], env=env, capture_output=True, text=True,
                            timeout=DEADLINE_S).stdout
    assert re.search(r"^\d+\. navtwin \(", listed, re.M), listed
    # no lab: tshark fails at once (the extcap opened Wireshark's FIFO before failing; tshark
    # shows its line, "cannot connect", when it reads the extcap's stderr in time)
    nolab = subprocess.run(["tshark", "-i", "navtwin", "-o",
                            f"extcap.navtwin.linkdir:{tmp_path}", "-w", str(tmp_path / "no")],
                           env=env, capture_output=True, text=True, timeout=DEADLINE_S)
    assert nolab.returncode != 0 and "0 packets captured" in nolab.stderr
    out = tmp_path / "live.pcapng"
    with emulate("office", seed=5, duration=60, record=tmp_path / "rec") as lab:
        # tshark stops the capture after 300 packets (it sends the extcap SIGTERM)
        cap = subprocess.run(["tshark", "-i", "navtwin", "-o",
                              f"extcap.navtwin.linkdir:{lab.info['link_dir']}", "-a",
                              "packets:300", "-w", str(out)],
                             env=env, capture_output=True, text=True, timeout=DEADLINE_S)
        assert lab.running()
    assert cap.returncode == 0, cap.stderr
    counts = assert_capture_is_the_recording(out.read_bytes(), Recording(tmp_path / "rec"))
    assert _tshark_counts(out) == counts
