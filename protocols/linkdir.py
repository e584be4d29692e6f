"""The link-directory rule shared by the emulator (which makes the links) and the host (which
follows them).

A link directory holds one symlink per port (``sins``, ``xbee``, ``nanoloc``) to a
``/dev/pts/N`` and the lock file :data:`LOCK`, which the emulator that made the links holds
(``flock(LOCK_EX)``) for as long as it runs. A kernel releases that lock when the process
dies, however it dies, so "the lock is held" is the one test of "the emulator is alive"
that survives ``kill -9``. A link whose emulator is gone points at a PTY number the kernel
may already have given to another program: nobody may open it.
"""
from __future__ import annotations

import fcntl
import os
import stat
from pathlib import Path

LOCK = ".lock"


def default_link_dir() -> Path:
    """``$XDG_RUNTIME_DIR/navtwin`` when that directory exists, else ``/tmp/navtwin-<uid>``."""
    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if runtime and os.path.isdir(runtime):
        return Path(runtime) / "navtwin"
    return Path("/tmp") / f"navtwin-{os.getuid()}"


def navtwin_link_dir(path: str | os.PathLike) -> Path | None:
    """The link directory if *path* is a navtwin link (a symlink in a directory holding
    :data:`LOCK`), else None: a device path, a pyserial URL, a missing file."""
    p = Path(path)
    try:
        if not stat.S_ISLNK(os.lstat(p).st_mode):
            return None
        os.lstat(p.parent / LOCK)
    except OSError:
        return None
    return p.parent


def emulator_alive(link_dir: str | os.PathLike) -> bool:
    """Whether an emulator holds *link_dir*'s lock. A lock that is missing, a symlink or not a
    regular file is held by no emulator (emulators refuse such a directory)."""
    try:
        fd = os.open(Path(link_dir) / LOCK,
                     os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        # free at once: an emulator starting now must get its exclusive lock
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)
