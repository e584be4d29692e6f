"""The host when writes fail, and `navtwin replay` of broken recordings (issue 7, points 4
and 6, and "host --record follows a symlink"): one line, exit 2, a summary, no traceback; a
recording closed and replayable up to what was written; damage reported, never replayed
silently; data files streamed."""
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

from navtwin.protocols.recording import Recording

from ..fs_helpers import fsize_limit
from ..helpers import NAVTWIN, run_cli
from ..lab import lab_bytes

DEADLINE_S = 60.0


def error_line(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [x for x in err.splitlines() if not x.startswith("{")]
    assert len(lines) == 1, err
    return lines[0]


def pty_pair():
    master, slave = os.openpty()
    path = os.ttyname(slave)
    os.close(slave)  # the host opens the slave by its path
    return master, path


class Host:
    """`navtwin host` as a subprocess on PTYs; waits for its "started" line."""

    def __init__(self, args, ports, **popen):
        self.masters, paths = {}, []
        for p in ports:
            self.masters[p], path = pty_pair()
            paths += [f"--{p}", path]
        self.proc = subprocess.Popen([*NAVTWIN, "host", *paths, *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, **popen)
        self.err = b""
        deadline = time.monotonic() + DEADLINE_S
        while b'"started"' not in self.err:
            assert time.monotonic() < deadline, f"host did not start: {self.err!r}"
            r, _, _ = select.select([self.proc.stderr], [], [], 1.0)
            if r:
                chunk = os.read(self.proc.stderr.fileno(), 65536)
                assert chunk, f"host exited early: {self.err!r}"
                self.err += chunk

    def feed(self, chunks, pause_s: float = 0.0) -> dict[str, bytes]:
        """Write (port, bytes, _) in the background until the host exits, *pause_s* after
        each; what was sent."""
        sent = {p: bytearray() for p in self.masters}

        def write():
            try:
                for port, data, _ in chunks:
                    view = memoryview(data)
                    while view:
                        _, w, _ = select.select([], [self.masters[port]], [], 0.2)
                        if self.proc.poll() is not None:
                            return
                        if w:
                            n = os.write(self.masters[port], view)
                            sent[port] += view[:n]
                            view = view[n:]
                    time.sleep(pause_s)
            except OSError:
                pass  # the host has gone and closed the line

        for m in self.masters.values():
            os.set_blocking(m, False)
        threading.Thread(target=write, daemon=True).start()
        return sent

    def finish(self) -> tuple[int, str, str]:
        try:
            out, err = self.proc.communicate(timeout=DEADLINE_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, err = self.proc.communicate()
            raise AssertionError(f"host did not end by itself: {(self.err + err)!r}")
        finally:
            for m in self.masters.values():
                os.close(m)
        return self.proc.returncode, out.decode(), (self.err + err).decode()


def summary_of(err: str) -> dict:
    lines = [json.loads(x) for x in err.splitlines() if x.startswith('{"summary"')]
    assert len(lines) == 1, err
    return lines[0]["summary"]


def test_host_out_to_a_full_device_ends_with_one_line_and_a_summary(tmp_path):
    host = Host(["--out", "/dev/full", "--record", tmp_path / "rec", "--status-period", "60"],
                ["xbee", "nanoloc"])
    host.feed(lab_bytes.office(30.0, 3))
    code, _, err = host.finish()
    assert code == 2, err
    line = error_line(err)
    assert line.startswith("navtwin host: error: --out /dev/full: No space left on device;")
    summary = summary_of(err)
    assert summary["error"].startswith("/dev/full: No space left on device")
    assert summary["chunks"] > 0
    rec = Recording(tmp_path / "rec")  # the recording of the run is closed and complete
    assert rec.complete and sum(len(c.data) for c in rec.chunks("xbee")) > 0


def test_host_record_on_a_full_filesystem_ends_cleanly_and_replays(tmp_path):
    d = tmp_path / "rec"
    host = Host(["--record", d, "--status-period", "60"], ["nanoloc"],
                preexec_fn=fsize_limit(32 << 10))
    # 200 KiB of noise at about 50 KiB/s: some flushes fit under the limit
    sent = host.feed([("nanoloc", bytes(range(256)) * 4, 0)] * 200, pause_s=0.02)
    code, _, err = host.finish()
    assert code == 2, err
    line = error_line(err)
    assert line.startswith(f"navtwin host: error: --record {d}/nanoloc.bin: File too large;")
    assert "ulimit -f" in line
    assert "nanoloc.bin" in summary_of(err)["error"]
    rec = Recording(d)
    assert not rec.complete
    got = rec.read_bytes("nanoloc")
    assert 0 < len(got) <= 32 << 10 and bytes(sent["nanoloc"]).startswith(got)
    res = subprocess.run([*NAVTWIN, "replay", d], capture_output=True, timeout=DEADLINE_S)
    assert res.returncode == 0, res.stderr
    assert b"is incomplete" in res.stderr and b"Traceback" not in res.stderr


def test_host_record_on_a_full_tmpfs_ends_cleanly_and_replays(small_fs):
    d = small_fs / "rec"
    host = Host(["--record", d, "--status-period", "60"], ["nanoloc"])
    sent = host.feed([("nanoloc", bytes(range(256)) * 4, 0)] * 1300, pause_s=0.004)
    code, _, err = host.finish()
    assert code == 2, err
    line = error_line(err)
    assert line.startswith(f"navtwin host: error: --record {d}/nanoloc.bin: No space left on "
                           f"device; the filesystem is full")
    assert "nanoloc.bin" in summary_of(err)["error"]
    rec = Recording(d)
    got = rec.read_bytes("nanoloc")
    assert not rec.complete and got and bytes(sent["nanoloc"]).startswith(got)


def test_host_refuses_to_record_through_a_symlink(capsys, tmp_path):
    master, path = pty_pair()
    try:
        target = tmp_path / "elsewhere"
        target.mkdir()
        (tmp_path / "link").symlink_to(target)
        code, _, err = run_cli(capsys, "host", "--sins", path, "--record", tmp_path / "link",
                               "--duration", "1")
    finally:
        os.close(master)
    assert code == 2
    assert "is a symbolic link" in error_line(err)
    assert not any(target.iterdir())


def test_replay_of_a_host_killed_with_sigkill(tmp_path):
    from navtwin.host.output import estimate_line
    from navtwin.host.pipeline import Pipeline
    from navtwin.host.replay import chunks, settings

    d, out = tmp_path / "rec", tmp_path / "live.jsonl"
    # the lines to a file: a stdout pipe nobody reads would fill and stall the host
    host = Host(["--record", d, "--out", out, "--status-period", "60"], ["xbee", "nanoloc"])
    office = list(lab_bytes.office(60.0, 5))
    host.feed(office, pause_s=0.001)  # 8,400 chunks: 8 s or more
    # a fifth of the coordinator's bytes recorded and flushed as the host runs (bytes, not
    # index lines: a loaded host reads fewer, bigger chunks)
    fifth = sum(len(data) for port, data, _ in office if port == "xbee") // 5
    deadline = time.monotonic() + DEADLINE_S
    while not (d / "xbee.bin").exists() or (d / "xbee.bin").stat().st_size < fifth:
        assert host.proc.poll() is None and time.monotonic() < deadline, host.err
        time.sleep(0.02)
    host.proc.kill()
    code, _, err = host.finish()
    assert code == -signal.SIGKILL
    live = out.read_text()
    rec = Recording(d)
    assert not rec.complete
    # the recording holds what the live run processed, in order: the same lines, cut
    kw = settings(rec)
    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), **kw)
    lines = [estimate_line(e) for port, data, t in chunks(rec, pipe.inputs)
             for e in pipe.feed(port, data, t)]
    assert len(lines) > 10 and "".join(lines) == live[:len("".join(lines))]
    res = subprocess.run([*NAVTWIN, "replay", d], capture_output=True, timeout=DEADLINE_S)
    assert res.returncode == 0 and res.stdout.decode().startswith("".join(lines)), res.stderr
    assert b"is incomplete" in res.stderr.splitlines()[0]


# -- replay of broken recordings -----------------------------------------------------------

@pytest.fixture
def golden_copy(root, tmp_path):
    d = tmp_path / "office"
    shutil.copytree(root / "fixtures" / "golden" / "office", d)
    return d


def edit_index_line(d, port, n, new: bytes):
    lines = (d / f"{port}.csv").read_bytes().splitlines()
    lines[n - 1] = new
    (d / f"{port}.csv").write_bytes(b"\n".join(lines) + b"\n")


def replay_error(capsys, d, *extra) -> str:
    code, out, err = run_cli(capsys, "replay", d, "--out", os.devnull, *extra)
    assert code == 2, err
    return error_line(err)


def test_replay_negative_offset(capsys, golden_copy):
    edit_index_line(golden_copy, "nanoloc", 3, b"-64,64,1000000,")
    assert "nanoloc.csv:3: expected non-negative integers" in replay_error(capsys, golden_copy)


def test_replay_offset_past_the_data(capsys, golden_copy):
    edit_index_line(golden_copy, "xbee", 5, b"100000000,6,20000000,")
    line = replay_error(capsys, golden_copy)
    assert "xbee.csv:5: offset 100000000 is not where the previous chunk ends" in line


def test_replay_size_ten_to_the_fifteen(capsys, golden_copy):
    first = (golden_copy / "nanoloc.csv").read_bytes().splitlines()[1].split(b",")
    edit_index_line(golden_copy, "nanoloc", 2, b",".join([first[0], b"%d" % 10 ** 15, *first[2:]]))
    assert "nanoloc.csv:2: size 1000000000000000 is not in" in replay_error(capsys, golden_copy)


def test_replay_negative_baud(capsys, golden_copy):
    meta = json.loads((golden_copy / "recording.json").read_text())
    meta["ports"]["nanoloc"]["baud"] = -115200
    (golden_copy / "recording.json").write_text(json.dumps(meta))
    assert "baud -115200 is not an integer from 50 to 4000000" in replay_error(capsys, golden_copy)


def test_replay_data_cut_in_half_under_an_intact_index(capsys, root, golden_copy):
    size = (golden_copy / "nanoloc.bin").stat().st_size
    os.truncate(golden_copy / "nanoloc.bin", size // 2)
    line = replay_error(capsys, golden_copy)
    assert "nanoloc.csv:" in line and "chunks past the end of nanoloc.bin" in line
    assert "--salvage" in line
    code, out, err = run_cli(capsys, "replay", golden_copy, "--salvage")
    assert code == 0, err
    assert "salvaged" in err.splitlines()[0]
    summary = json.loads(err.splitlines()[-1])["summary"]
    assert summary["skipped"]["nanoloc"]["chunks"] > 0 and summary["complete"]
    # the salvaged run is the full run's until the cut (ranges stop at about half time)
    cut_s = max(c.t_device_ns for c in Recording(golden_copy, salvage=True).chunks("nanoloc")) / 1e9
    full = run_cli(capsys, "replay", root / "fixtures" / "golden" / "office")[1]
    before = [x for x in full.splitlines() if json.loads(x)["t"] < cut_s]
    assert len(before) > 100 and out.splitlines()[:len(before)] == before


def test_replay_broken_pipe_ends_quietly(root):
    proc = subprocess.Popen([*NAVTWIN, "replay", root / "fixtures" / "golden" / "office"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.readline()
    proc.stdout.close()  # as `| head -1` does
    _, err = proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 0 and b"Traceback" not in err, err


def test_replay_of_a_sparse_3_gib_data_file_streams(golden_copy):
    os.truncate(golden_copy / "xbee.bin", 3 << 30)  # the index names its first 47 KB
    # VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec, so it would count the
    # forking test process's own memory
    code = ("import re, sys; from navtwin.cli.main import main; rc = main(sys.argv[1:]); "
            "print(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read())[1], "
            "file=sys.stderr); sys.exit(rc)")
    res = subprocess.run([sys.executable, "-c", code, "replay", str(golden_copy), "--out",
                          os.devnull], capture_output=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    err = res.stderr.decode().splitlines()
    peak_kib = int(err[-1])
    assert peak_kib < 400 << 10, f"peak RSS {peak_kib} KiB"  # the file is 3 GiB
    unindexed = (3 << 30) - sum(len(c.data) for c in Recording(golden_copy).chunks("xbee"))
    assert "has extra bytes" in err[0] and f"xbee: 0 chunks, {unindexed} bytes" in err[0]
