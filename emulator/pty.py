"""Pseudo-terminal ports with stable links: the lab's serial lines as the host sees them.

Each port is the master side of a Linux PTY. The emulator never keeps the slave open, so
the kernel tells it whether a client is attached (``POLLHUP`` on the master means no slave
fd is open). The slave is put in raw mode once (termios persist across reopen) and opened
and closed once at creation, because a never-opened slave raises no HUP.

Line discipline of the emulated cable (peers-and-pty-facts.md section 5):

* unplugged: while no client has the port open, the device's output is dropped and
  counted (``dropped_unplugged``), as on a line with nothing at the other end;
* no stale bytes: the slave's input queue outlives its clients (the kernel keeps what a
  client left unread for the next opener), so it is flushed (``tcflush(TCIFLUSH)`` on a
  short-lived ``O_NOCTTY`` slave fd) as soon as a client is seen gone, and again when one
  is seen attaching: a client that reads at once after its open gets only bytes written
  after it (a bare ``os.read`` or ``cat`` flushes nothing, unlike pyserial). Left open: a
  client that opens between another's close and the emulator noticing it (the loop wakes
  on the hang-up, well under a millisecond when idle) gets what that one left;
* overflow: the master is ``O_NONBLOCK``; when the client does not read and the kernel
  buffer (about 20 KiB) is full, the bytes that do not fit are dropped and counted
  (``dropped_overflow``), as a UART loses what the host does not read. The emulator never
  blocks on a client;
* unplug, as a USB serial adapter's on Linux: the line goes quiet at once (the device's
  output is dropped as unplugged, the link removed), then the kernel hangs the readers up
  (the master is closed: ``tty_vhangup``, exactly as ``usb_serial_disconnect`` does):
  ``poll`` gives POLLHUP|POLLERR, ``read`` end of file, ``write`` EIO. The hang-up waits
  until the client has read what was sent and the line has been quiet ``HANGUP_QUIET_NS``
  (at most ``HANGUP_MAX_NS``): a hung-up tty reads 0 bytes forever, so a reader caught
  between a read and its next poll (node serialport loops on such reads) would never see
  POLLERR, while one waiting in ``poll`` sees it at once;
* a detached master reads EIO and ``select`` reports it readable forever, so only
  attached ports are waited on; detached ones are re-checked with :meth:`PtyPort.check`;
* the client's settings: termios ioctls on the master act on the slave, so
  :meth:`PtyPort.client_framing` reads the baud, data bits, parity and stop bits the client
  set (one ``tcgetattr``; the runner looks every ``CHECK_NS``), read as a UART reads them
  (:meth:`Framing.from_cflag`). The PTY driver forces CS8 and clears PARENB on every set
  (``pty_set_termios``), so 7 data bits and parity never show (the PARODD it leaves is no
  parity to a UART, whichever client left it); baud and CSTOPB show as set.

:class:`LinkDir` is the directory of stable symlinks (``sins``, ``xbee``, ``nanoloc``) to
the ``/dev/pts/N`` paths: created 0700, refused when owned by another user or writable by
group or others, locked (``flock`` on :data:`navtwin.protocols.linkdir.LOCK`, a regular file of
ours opened without following a symlink) while an emulator uses it. Once it holds the lock
it removes the links a dead run left (symlinks named like a port pointing into
``/dev/pts/``), so while the lock is held the links are absent or this run's: the host
follows a link only then. Anything else under a port's name is refused, never deleted.
"""
from __future__ import annotations

import errno
import fcntl
import os
import select
import stat
import struct
import termios
import time
import tty
from collections.abc import Iterable
from pathlib import Path

from navtwin.protocols.linkdir import LOCK, default_link_dir
from navtwin.protocols.ports import DEFAULT_BAUD

from .uart_rx import Framing

PTS = "/dev/pts/"  # where every PTY slave an emulator links to lives
LOCK_TRIES = 20  # a host's probe holds the lock shared for microseconds: retry ...
LOCK_RETRY_S = 0.005  # ... this often before calling the directory in use
#: termios speed constants -> baud (B0, "hang up", is left out: no rate to read at)
SPEED_BAUD = {getattr(termios, n): int(n[1:]) for n in dir(termios)
              if n.startswith("B") and n[1:].isdigit() and int(n[1:]) > 0}
BOTHER = 0o010000  # a rate that is no B constant (pyserial's 250000): read it with TCGETS2
TERMIOS2 = struct.Struct("4IB19s2I")  # struct termios2: flags, c_line, c_cc, c_ispeed, c_ospeed
TCGETS2 = 2 << 30 | TERMIOS2.size << 16 | ord("T") << 8 | 0x2A  # _IOR('T', 0x2A, termios2)
HANGUP_QUIET_NS = 50_000_000  # unplug: the client's queue empty this long, then the hang-up
HANGUP_MAX_NS = 1_000_000_000  # ... or this long after the pull (a client that never reads)


class LinkDirError(ValueError):
    """A link directory the emulator must not use; the message is one line with the fix."""


class LinkDir:
    """A private directory of symlinks to PTY slaves, held by one emulator at a time.

    *names* are the ports this run will link: their stale links are removed (and anything
    that is not a link of ours refused) before the caller creates its PTYs."""

    def __init__(self, path: str | os.PathLike | None = None, names: Iterable[str] = ()) -> None:
        self.path = Path(path) if path is not None else default_link_dir()
        self._created = False
        self._lock = -1
        self.links: dict[str, str] = {}
        try:
            os.mkdir(self.path, 0o700)
            self._created = True
        except FileExistsError:
            pass
        except OSError as e:
            raise LinkDirError(f"link_dir: cannot create link directory {self.path} "
                               f"({e.strerror}); choose a writable path") from None
        st = os.lstat(self.path)
        if not stat.S_ISDIR(st.st_mode):
            raise LinkDirError(f"link_dir: {self.path} is not a directory; choose another path")
        if st.st_uid != os.getuid():
            raise LinkDirError(f"link_dir: {self.path} is owned by uid {st.st_uid}, not you; "
                               f"choose a directory of your own")
        if st.st_mode & 0o022:
            raise LinkDirError(f"link_dir: {self.path} is writable by others "
                               f"(mode {stat.S_IMODE(st.st_mode):04o}); chmod 700 it or choose "
                               f"another link directory")
        try:
            self._take_lock()
            for name in names:
                if self._ours(name):
                    (self.path / name).unlink()  # a dead run's: its PTY may be anyone's now
        except BaseException:
            self.close()
            raise

    def _refuse(self, name: str, what: str) -> LinkDirError:
        return LinkDirError(f"link_dir: {self.path / name} {what}; remove it or choose another link "
                            "directory")

    def _take_lock(self) -> None:
        try:  # O_NOFOLLOW: a symlinked lock must not make us truncate the file it points at
            fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK
                         | os.O_CLOEXEC, 0o600)
        except OSError as e:
            what = "is a symlink" if e.errno == errno.ELOOP else f"cannot be opened ({e.strerror})"
            raise self._refuse(LOCK, what) from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1 or st.st_uid != os.getuid():
                raise self._refuse(LOCK, "is not a regular file of yours")
            for _ in range(LOCK_TRIES):
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    time.sleep(LOCK_RETRY_S)
            else:
                other = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
                raise LinkDirError(f"link_dir: {self.path} is in use by another emulator "
                                   f"(pid {other}); stop it or choose another link directory")
        except BaseException:
            os.close(fd)  # not ours: close() must leave the file where it is
            raise
        self._lock = fd
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)

    def _ours(self, name: str) -> bool:
        """Whether ``DIR/name`` is a link to a PTY (True) or absent (False); refuses the rest."""
        path = self.path / name
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            return False
        if stat.S_ISLNK(st.st_mode):
            target = os.readlink(path)
            if target.startswith(PTS):
                return True
            raise self._refuse(name, f"is a link to {target}, not to a PTY")
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else \
            "a regular file" if stat.S_ISREG(st.st_mode) else "not a link"
        raise self._refuse(name, f"is {kind}, not a link navtwin made")

    def link(self, name: str, target: str) -> Path:
        """Point ``DIR/name`` at *target*, atomically replacing an older link to a PTY."""
        self._ours(name)
        final = self.path / name
        tmp = self.path / f".{name}.{os.getpid()}.tmp"
        try:
            try:
                tmp.unlink()
            except FileNotFoundError:
                pass
            os.symlink(target, tmp)
            os.replace(tmp, final)
        except OSError as e:
            raise self._refuse(tmp.name, f"cannot be made ({e.strerror})") from None
        self.links[name] = target
        return final

    def unlink(self, name: str) -> None:
        """Remove link *name* (an unplugged port: its device node vanishes)."""
        target = self.links.pop(name, None)
        final = self.path / name
        try:
            if target is not None and os.readlink(final) == target:
                final.unlink()
        except OSError:
            pass

    def close(self) -> None:
        """Remove the links this emulator made (if still ours), the lock, and a dir it created."""
        for name, target in self.links.items():
            final = self.path / name
            try:
                if os.readlink(final) == target:
                    final.unlink()
            except OSError:
                pass
        self.links.clear()
        if self._lock >= 0:
            try:
                (self.path / LOCK).unlink()
            except OSError:
                pass
            os.close(self._lock)
            self._lock = -1
        if self._created:
            try:
                self.path.rmdir()
            except OSError:
                pass  # something else lives there; leave it


class PtyPort:
    """The master side of one PTY in raw mode; see the module docstring for the policy."""

    def __init__(self, name: str, baud: int = DEFAULT_BAUD) -> None:
        self.name = name
        self.baud = baud
        self.fd = -1
        self.pts = ""
        self.attached = False
        self.attaches = 0
        self.written = 0
        self.dropped_unplugged = 0
        self.dropped_overflow = 0
        self.received = 0
        self.unplugs = 0
        self._pulled: tuple[int, int] | None = None  # unplugging: (when, a slave fd) until hung up
        self._quiet_since = 0
        #: the client's termios (iflag, cflag, ispeeds) last read and what they gave: the
        #: runner reads them every CHECK_NS, and they seldom change
        self._termios: tuple | None = None
        self._framing: tuple[Framing | None, int] = (None, 0)
        self._open()

    def _open(self) -> None:
        master, slave = os.openpty()
        self.pts = os.ttyname(slave)
        tty.setraw(slave)
        attrs = termios.tcgetattr(slave)
        speed = getattr(termios, f"B{self.baud}", None)
        if speed is not None:  # cosmetic: tools that query the line see the port's rate
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(slave, termios.TCSANOW, attrs)
        os.close(slave)  # from now on HUP says "no client" (a never-opened slave shows none)
        os.set_blocking(master, False)
        self.fd = master
        self.attached = False

    @property
    def plugged(self) -> bool:
        return self.fd >= 0 and self._pulled is None

    def unplug(self) -> None:
        """Pull the cable: what the device writes from now on is dropped and counted as
        unplugged, and the PTY goes away once its client is back waiting (:meth:`check`;
        module docstring)."""
        if self.plugged:
            try:  # to see the client's queue (FIONREAD) until the hang-up
                probe = os.open(self.pts, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK | os.O_CLOEXEC)
            except OSError:
                probe = -1
            self._pulled = (time.monotonic_ns(), probe)
            self._quiet_since = 0
            self.attached = False
            self.unplugs += 1

    def _hang_up_when_quiet(self) -> None:
        pulled, probe = self._pulled
        now = time.monotonic_ns()
        try:
            queued = struct.unpack("i", fcntl.ioctl(probe, termios.FIONREAD, bytes(4)))[0]
        except OSError:
            queued = 0
        if queued:
            self._quiet_since = 0
        elif not self._quiet_since:
            self._quiet_since = now
        if (self._quiet_since and now - self._quiet_since >= HANGUP_QUIET_NS
                or now - pulled >= HANGUP_MAX_NS):
            self.close()

    def replug(self) -> str:
        """Plug it back: a new PTY (a new /dev/pts/N, as a USB adapter comes back under a
        new node); returns its path."""
        if not self.plugged:
            self.close()  # an unplug still waiting to hang up does it now
            self._open()
        return self.pts

    def fileno(self) -> int:
        return self.fd

    def check(self) -> bool:
        """Refresh and return ``attached`` (one non-blocking poll of the master); while
        unplugging, hang the client up once it is quiet."""
        if self._pulled is not None:
            self._hang_up_when_quiet()
        if not self.plugged:
            return False
        p = select.poll()
        p.register(self.fd, select.POLLIN)
        hup = any(ev & select.POLLHUP for _, ev in p.poll(0))
        if not hup and not self.attached:
            self._flush_stale()
            self.attached = True
            self.attaches += 1
        elif hup and self.attached:
            self._detach()
        return self.attached

    def _detach(self) -> None:
        self.attached = False
        self._flush_stale()  # what the client left must not wait for the next opener

    def client_framing(self) -> tuple[Framing | None, int]:
        """The client's (Framing, c_iflag) from the slave's termios; Framing None when
        the rate is B0 (hang up) or unreadable. Settings read as before give the same
        objects (the runner then has nothing to settle)."""
        try:
            iflag, _, cflag, _, ispeed, ospeed, _ = termios.tcgetattr(self.fd)
            speed = ispeed or ospeed  # an input speed of 0 means "as the output"
            if (iflag, cflag, ispeed, ospeed) == self._termios:
                return self._framing
            baud = SPEED_BAUD.get(speed)
            if speed == BOTHER:  # the rate is in termios2, not in what was compared
                raw = fcntl.ioctl(self.fd, TCGETS2, bytes(TERMIOS2.size))
                _, _, _, _, _, _, ibaud, obaud = TERMIOS2.unpack(raw)
                baud = ibaud or obaud or None
        except OSError:
            return None, 0
        framing = (None if baud is None else Framing.from_cflag(baud, cflag)), iflag
        if speed != BOTHER:
            self._termios, self._framing = (iflag, cflag, ispeed, ospeed), framing
        return framing

    def _flush_stale(self) -> None:
        try:
            fd = os.open(self.pts, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError:
            return
        try:
            termios.tcflush(fd, termios.TCIFLUSH)
        finally:
            os.close(fd)

    def write(self, data: bytes) -> int:
        """Send *data* to the client; returns how many bytes got through (the rest is counted)."""
        if not self.attached:
            self.dropped_unplugged += len(data)
            return 0
        try:
            n = os.write(self.fd, data)
        except BlockingIOError:
            n = 0
        except OSError as e:
            if e.errno != errno.EIO:
                raise
            n = 0
        self.written += n
        self.dropped_overflow += len(data) - n
        return n

    def read(self) -> bytes:
        """What the client wrote, without blocking. EIO (client gone) marks the port detached."""
        out = bytearray()
        if not self.plugged:
            return b""
        while True:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            except OSError as e:
                if e.errno != errno.EIO:
                    raise
                if self.attached:
                    self._detach()
                break
            if not chunk:
                break
            out += chunk
        self.received += len(out)
        return bytes(out)

    def stats(self) -> dict:
        return {"pts": self.pts, "attaches": self.attaches, "written": self.written,
                "dropped_unplugged": self.dropped_unplugged,
                "dropped_overflow": self.dropped_overflow, "received": self.received,
                "unplugs": self.unplugs}

    def close(self) -> None:
        if self._pulled is not None:
            if self._pulled[1] >= 0:
                os.close(self._pulled[1])  # before the master: the hang-up must reach no fd of ours
            self._pulled = None
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
