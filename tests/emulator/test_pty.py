"""PTY ports and the link directory: raw line, unplugged and overflow policies, no stale
bytes, atomic links, refusal of unsafe directories."""
import fcntl
import os
import select
import stat
import struct
import termios
import time

import pytest

from navtwin.emulator.api import emulate
from navtwin.emulator.pty import LinkDir, LinkDirError, PtyPort
from navtwin.protocols.stream import sins_decoder

pytestmark = pytest.mark.pty
DEADLINE = 10.0


def client(port: PtyPort) -> int:
    """A client opening the slave the way a C program would (no raw mode of its own)."""
    return os.open(port.pts, os.O_RDWR | os.O_NOCTTY)


def read_exactly(fd: int, n: int, deadline: float = DEADLINE) -> bytes:
    out = b""
    end = time.monotonic() + deadline
    while len(out) < n:
        r, _, _ = select.select([fd], [], [], max(0.0, end - time.monotonic()))
        if not r:
            break
        out += os.read(fd, n - len(out))
    return out


def nothing_to_read(fd: int) -> bool:
    return not select.select([fd], [], [], 0.2)[0]


def wait_for(cond, deadline: float = DEADLINE) -> bool:
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        if cond():
            return True
        select.select([], [], [], 0.005)
    return cond()


@pytest.fixture
def port():
    p = PtyPort("sins")
    yield p
    p.close()


def test_slave_is_raw_and_silent(port):
    fd = client(port)
    try:
        assert port.check()
        attrs = termios.tcgetattr(fd)
        assert not attrs[3] & (termios.ICANON | termios.ECHO)
        assert attrs[4] == termios.B115200
        port.write(b"AB\r\n\x03\x11")
        assert read_exactly(fd, 6) == b"AB\r\n\x03\x11"  # no CR/LF mapping, no signals, no XON
        os.write(fd, b"\r\x13")
        assert wait_for(lambda: select.select([port.fd], [], [], 0)[0])
        assert port.read() == b"\r\x13"  # the master gets no echo of its own bytes
    finally:
        os.close(fd)


def test_output_is_lost_while_unplugged_and_never_queued(port):
    assert not port.check()
    assert port.write(b"nobody listens") == 0
    assert port.dropped_unplugged == 14
    fd = client(port)
    try:
        assert port.check()
        port.write(b"fresh")
        assert read_exactly(fd, 5) == b"fresh"
        assert nothing_to_read(fd)
    finally:
        os.close(fd)


def test_a_new_client_never_reads_what_the_last_one_left(port):
    fd = client(port)
    assert port.check()
    port.write(b"left unread by the first client")
    os.close(fd)
    assert not port.check()
    port.write(b"while unplugged")
    fd = client(port)
    try:
        assert port.check() and port.attaches == 2
        port.write(b"new")
        assert read_exactly(fd, 3) == b"new"
        assert nothing_to_read(fd)
    finally:
        os.close(fd)


@pytest.mark.parametrize("noticed_by", ["check", "read"])
def test_what_a_client_left_is_gone_before_the_next_open(port, noticed_by):
    """A reader that reads at once after its open, before the emulator has seen it, must
    not get what the last client left: the queue is flushed when that one is seen gone."""
    fd = client(port)
    assert port.check()
    port.write(b"left unread by the first client")
    os.close(fd)
    if noticed_by == "check":  # the runner's look at the ports
        assert wait_for(lambda: not port.check())
    else:  # the runner's read of the master: EIO
        assert wait_for(lambda: select.select([port.fd], [], [], 0)[0])
        assert port.read() == b"" and not port.attached
    fd = client(port)
    try:
        assert nothing_to_read(fd)
    finally:
        os.close(fd)


def _pending(fd: int) -> int:
    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, bytes(4)))[0]


def test_a_hundred_immediate_reads_after_open_get_no_stale_frame(tmp_path):
    """Each client reads at once after its open (no flush of its own, as cat or C do), then
    leaves frames unread and closes; the next opener must get none of them."""
    frame = 30  # bytes of a SINS sample frame
    stale = []
    with emulate("office", duration=70, link_dir=tmp_path / "links") as lab:
        link = lab.ports["sins"]
        left = -1  # the highest seq the last client left unread
        for i in range(100):
            fd = os.open(link, os.O_RDWR | os.O_NOCTTY)
            try:
                dec, seqs = sins_decoder(), []
                end = time.monotonic() + DEADLINE
                while not seqs and time.monotonic() < end:  # the immediate read, then more
                    seqs += [f.fields["seq"] for f in dec.feed(os.read(fd, 65536))
                             if hasattr(f, "fields")]
                assert seqs, f"open {i}: no frame within {DEADLINE} s"
                stale += [(i, s) for s in seqs if s <= left]
                while select.select([fd], [], [], 0)[0]:  # take what came meanwhile ...
                    seqs += [f.fields["seq"] for f in dec.feed(os.read(fd, 65536))
                             if hasattr(f, "fields")]
                assert wait_for(lambda: _pending(fd) >= 2 * frame)  # ... and leave two frames
                left = seqs[-1] + _pending(fd) // frame
            finally:
                os.close(fd)
            end = time.monotonic() + DEADLINE  # the emulator notices the close
            while lab.status()["ports"]["sins"]["attached"]:
                assert time.monotonic() < end, "the emulator never noticed the close"
                time.sleep(0.002)
    assert stale == []


def test_a_client_that_does_not_read_never_blocks_the_emulator(port):
    fd = client(port)
    try:
        port.check()
        chunk = bytes(1000)
        for _ in range(100):  # 100 kB, five times the kernel's buffer
            port.write(chunk)
        assert port.written + port.dropped_overflow == 100_000
        assert 4096 <= port.written < 100_000 and port.dropped_overflow > 0
    finally:
        os.close(fd)


def test_client_leaving_is_noticed_and_its_last_words_are_read(port):
    fd = client(port)
    port.check()
    os.write(fd, b"bye")
    os.close(fd)
    assert wait_for(lambda: select.select([port.fd], [], [], 0)[0])
    assert port.read() == b"bye"
    assert port.read() == b""  # EIO now: treated as unplugged, not an error
    assert not port.attached and not port.check()
    assert port.write(b"x") == 0


def test_open_close_storm(port):
    for i in range(50):
        fd = client(port)
        port.check()
        port.write(b"%d" % i)
        if i % 2:
            os.write(fd, b"garbage")
        os.close(fd)
        port.read()
        port.check()
    fd = client(port)
    try:
        assert port.check()
        port.write(b"still alive")
        assert read_exactly(fd, 11) == b"still alive"
    finally:
        os.close(fd)


# -- link directory ----------------------------------------------------------------------

def test_link_dir_is_private_links_are_atomic_and_removed(tmp_path):
    d = tmp_path / "links"
    os.symlink("/dev/pts/nonexistent", tmp_path / "stale")
    ld = LinkDir(d)
    assert stat.S_IMODE(os.stat(d).st_mode) == 0o700
    os.symlink("/dev/pts/9999", d / "sins")  # left by a dead run
    link = ld.link("sins", "/dev/pts/1")
    assert os.readlink(link) == "/dev/pts/1"
    ld.link("sins", "/dev/pts/2")
    assert os.readlink(link) == "/dev/pts/2"
    assert sorted(os.listdir(d)) == [".lock", "sins"]  # no temporary names left behind
    ld.close()
    assert not d.exists()  # it created the directory, so it removes it


def test_link_dir_keeps_a_directory_it_did_not_create(tmp_path):
    d = tmp_path / "mine"
    d.mkdir(mode=0o700)
    (d / "notes.txt").write_text("keep me")
    ld = LinkDir(d)
    ld.link("xbee", "/dev/pts/3")
    ld.close()
    assert sorted(os.listdir(d)) == ["notes.txt"]


def test_link_dir_does_not_remove_a_link_someone_else_replaced(tmp_path):
    ld = LinkDir(tmp_path / "l")
    ld.link("xbee", "/dev/pts/3")
    os.replace(_symlink(tmp_path / "other", "/dev/pts/4"), tmp_path / "l" / "xbee")
    ld.close()
    assert os.readlink(tmp_path / "l" / "xbee") == "/dev/pts/4"


def _symlink(path, target):
    os.symlink(target, path)
    return path


def test_link_dir_in_use_is_refused_with_one_line(tmp_path):
    first = LinkDir(tmp_path / "l")
    try:
        with pytest.raises(LinkDirError) as e:
            LinkDir(tmp_path / "l")
        msg = str(e.value)
        assert "\n" not in msg and f"pid {os.getpid()}" in msg and msg.startswith("link_dir: ")
    finally:
        first.close()
    LinkDir(tmp_path / "l").close()  # free again once the first has gone


@pytest.mark.parametrize("mode", [0o777, 0o720, 0o702])
def test_writable_by_others_is_refused(tmp_path, mode):
    d = tmp_path / "open"
    d.mkdir()
    os.chmod(d, mode)
    with pytest.raises(LinkDirError, match="writable by others.*chmod 700"):
        LinkDir(d)


def test_owned_by_someone_else_is_refused(tmp_path):
    if os.getuid() != 0:
        pytest.skip("needs root to give a directory away")
    d = tmp_path / "theirs"
    d.mkdir(mode=0o700)
    os.chown(d, 4321, 4321)
    with pytest.raises(LinkDirError, match="owned by uid 4321"):
        LinkDir(d)


def test_not_a_directory_is_refused(tmp_path):
    f = tmp_path / "file"
    f.write_text("")
    with pytest.raises(LinkDirError, match="not a directory"):
        LinkDir(f)
