"""The link directory's files before use: the lock and the port names hold only what navtwin
made; what it did not make is refused with one line and left alone; a dead run's links are
gone while the lock is held; the host's test of "is the emulator alive"."""
import os
import threading

import pytest

from navtwin.emulator.pty import LinkDir, LinkDirError
from navtwin.protocols.ports import names
from navtwin.protocols.linkdir import LOCK, emulator_alive, navtwin_link_dir

from ..helpers import navtwin, one_line_error

PORTS = names()  # the lab's ports, in its order


def emulate(link_dir):
    return navtwin("emulate", "--scenario", "office", "--speed", "max", "--duration", "0.2",
                   "--quiet", "--link-dir", link_dir)


def private_dir(tmp_path):
    d = tmp_path / "links"
    d.mkdir(mode=0o700)
    return d


def _file(d):
    (d / "xbee").write_text("my notes\n")
    return "a regular file"


def _dir(d):
    (d / "xbee").mkdir()
    (d / "xbee" / "inside").write_text("keep\n")
    return "a directory"


def _elsewhere(d):
    os.symlink("/dev/null", d / "xbee")
    return "a link to /dev/null"


@pytest.mark.parametrize("make", [_file, _dir, _elsewhere], ids=["file", "directory", "link"])
def test_what_navtwin_did_not_make_at_a_ports_name_is_refused_and_kept(tmp_path, make):
    d = private_dir(tmp_path)
    what = make(d)
    before = os.lstat(d / "xbee")
    line = one_line_error(emulate(d), str(d / "xbee"), what, "remove it", "--link-dir")
    assert "--record" not in line
    after = os.lstat(d / "xbee")
    assert (after.st_ino, after.st_mode, after.st_size) == \
        (before.st_ino, before.st_mode, before.st_size)
    assert sorted(os.listdir(d)) == ["xbee"]  # no lock, no link of ours left behind


def test_a_symlinked_lock_is_refused_and_its_target_untouched(tmp_path):
    d = private_dir(tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    os.symlink(victim, d / LOCK)
    one_line_error(emulate(d), str(d / LOCK), "symlink", "--link-dir")
    assert victim.read_text() == "precious\n"
    assert os.readlink(d / LOCK) == str(victim)



def test_a_dangling_symlinked_lock_is_not_created_through(tmp_path):
    d = private_dir(tmp_path)
    dangling = tmp_path / "nowhere"
    os.symlink(dangling, d / LOCK)
    one_line_error(emulate(d), str(d / LOCK), "symlink")
    assert not dangling.exists()


@pytest.mark.parametrize("kind", ["fifo", "hardlink"])
def test_a_lock_that_is_not_a_regular_file_of_ours_is_refused(tmp_path, kind):
    d = private_dir(tmp_path)
    if kind == "fifo":
        os.mkfifo(d / LOCK)
    else:
        (tmp_path / "other").write_text("x\n")
        os.link(tmp_path / "other", d / LOCK)
    with pytest.raises(LinkDirError, match="not a regular file of yours"):
        LinkDir(d, PORTS)
    assert os.path.lexists(d / LOCK)  # refused, not removed
    if kind == "hardlink":
        assert (tmp_path / "other").read_text() == "x\n"


def test_a_dead_runs_links_are_removed_once_the_lock_is_taken(tmp_path):
    d = private_dir(tmp_path)
    (d / LOCK).write_text("4242\n")  # a killed emulator's
    for name in PORTS:
        os.symlink(f"/dev/pts/{900 + len(name)}", d / name)
    os.symlink("/dev/pts/7", d / "mine")  # not a port name: not ours to judge
    ld = LinkDir(d, PORTS)
    try:
        assert sorted(os.listdir(d)) == [LOCK, "mine"]
        assert emulator_alive(d)
    finally:
        ld.close()
    assert sorted(os.listdir(d)) == ["mine"]


def test_alive_is_the_lock_being_held(tmp_path):
    d = private_dir(tmp_path)
    assert navtwin_link_dir(d / "xbee") is None and not emulator_alive(d)
    ld = LinkDir(d, PORTS)
    ld.link("xbee", "/dev/pts/5")
    assert navtwin_link_dir(d / "xbee") == d and emulator_alive(d)
    os.close(ld._lock)  # the process dies: the kernel lets the lock go, the files stay
    ld._lock = -1
    assert navtwin_link_dir(d / "xbee") == d and not emulator_alive(d)
    assert navtwin_link_dir(d / LOCK) is None  # a regular file, not a link
    assert navtwin_link_dir("socket://localhost:1") is None


def test_a_hosts_probes_do_not_make_a_starting_emulator_fail(tmp_path):
    d = private_dir(tmp_path)
    stop, probes = threading.Event(), [0]

    def probe():  # a host waiting for an emulator: emulator_alive() as fast as it can go
        while not stop.is_set():
            emulator_alive(d)
            probes[0] += 1

    t = threading.Thread(target=probe)
    t.start()
    try:
        for _ in range(300):
            LinkDir(d, PORTS).close()
    finally:
        stop.set()
        t.join()
    assert probes[0] > 100
