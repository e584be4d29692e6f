"""A running lab in Wireshark: the extcap interface protocol over the lab's tap (emulator.tap).

Wireshark (and tshark, dumpcap) runs each program in its extcap folder in steps
(wireshark.org, extcap(4))::

    --extcap-interfaces [--extcap-version=V]   extcap {version}{help} and one interface line
    --extcap-dlts --extcap-interface navtwin    the interface's link type
    --extcap-config --extcap-interface navtwin  its options: the lab's link directory
    --capture --extcap-interface navtwin --fifo PATH [--link-dir DIR]
              [--extcap-capture-filter "sins xbee"]
                                                pcapng into PATH until the lab ends, or
                                                SIGTERM (Stop), or the reader closes PATH

One interface, ``navtwin``: a lab's link directory is private (``mkdtemp`` for the pytest
plugin, or any ``--link-dir``), so labs cannot be listed; the interface's option picks the
link directory, by default the one ``navtwin emulate`` uses without ``--link-dir``. Its
capture is pcapng with one Wireshark interface per port (protocols.capture: the link types
the shipped dissectors decode) and per declared stream (the radio's air), packets stamped
with device time, both directions. The capture filter, if any, names the ports or streams to
keep, separated by spaces or commas. The interface's link type listed for ``--extcap-dlts``
is the first port's: the pcapng's own interface blocks give each port's.
"""
from __future__ import annotations

import contextlib
import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
from pathlib import Path

from navtwin.protocols import __version__, ports
from navtwin.protocols.capture import Capture, linktype
from navtwin.protocols.linkdir import default_link_dir
from navtwin.protocols.pcapng import LINKTYPE_USER0

from .tap import STREAM, TapClient, TapError

INTERFACE = "navtwin"
#: the interface's help in Wireshark: the guide's section, where the docs are installed
GUIDE = Path(__file__).resolve().parent.parent / "docs" / "testing.md"
WRAPPER = "navtwin"  # the program's name in Wireshark's extcap folder


class ExtcapError(ValueError):
    """A request Wireshark or the user made that cannot be done; one line with the fix."""


def _field(**fields) -> str:
    return "".join(f"{{{k}={v}}}" for k, v in fields.items())


def interfaces() -> list[str]:
    """The ``--extcap-interfaces`` lines."""
    names = ", ".join(ports.names())
    help_ = {"help": GUIDE.as_uri()} if GUIDE.is_file() else {}
    return [f"extcap {_field(version=__version__, **help_)}",
            f"interface {_field(value=INTERFACE, display=f'navtwin lab ({names}, live)')}"]


def check_interface(interface: str | None) -> None:
    if interface != INTERFACE:
        raise ExtcapError(f"extcap_interface: {interface!r} is not an interface of navtwin; "
                          f"use {INTERFACE}")


def dlts(interface: str | None) -> list[str]:
    """The ``--extcap-dlts`` lines of *interface*."""
    check_interface(interface)
    number = linktype(ports.listed()[0].name, {})
    return ["dlt " + _field(number=number, name=f"USER{number - LINKTYPE_USER0}",
                            display="navtwin ports (pcapng: one interface per port)")]


def config(interface: str | None) -> list[str]:
    """The ``--extcap-config`` lines of *interface*: its one option, the link directory."""
    check_interface(interface)
    return ["arg " + _field(number=0, call="--link-dir", display="Link directory",
                            tooltip="the running lab's link directory (navtwin emulate "
                                    "--link-dir; its ready line's link_dir)",
                            type="string", default=default_link_dir())]


def selection(capture_filter: str | None) -> set[str] | None:
    """The names a capture filter keeps (None: all)."""
    if capture_filter is None or not capture_filter.strip():
        return None
    return set(re.split(r"[\s,]+", capture_filter.strip()))


def capture(link_dir: str | os.PathLike, fifo: str | os.PathLike,
            keep: set[str] | None = None) -> bool:
    """Write the lab's chunks on *link_dir*'s tap into *fifo* (Wireshark's FIFO, or a file)
    as pcapng, flushed per packet, until the run ends; True if it ended (the tap's end
    record), False if the lab closed the tap first (this capture fell behind and was
    dropped, or the lab died). TapError if no lab runs there (before *fifo* is opened); a
    reader that closes *fifo* raises BrokenPipeError.

    A FIFO is opened first: Wireshark's reader waits for its writer, and sees a failure only
    once the FIFO closes (an extcap that exits without opening it hangs tshark). A file is
    opened only once the lab answered, so a failed capture leaves none."""
    with contextlib.ExitStack() as opened:
        out = opened.enter_context(open(fifo, "wb")) if _is_fifo(fifo) else None
        tap = opened.enter_context(TapClient(link_dir, timeout=None))
        hello = tap.hello
        if keep is not None and (unknown := keep - set(hello["ports"]) - set(hello["streams"])):
            raise ExtcapError(f"extcap_capture_filter: no port or stream "
                              f"{', '.join(sorted(unknown))} in this lab; name some of "
                              f"{', '.join([*hello['ports'], *hello['streams']])}")
        if out is None:
            out = opened.enter_context(open(fifo, "wb"))
        return _write(tap, Capture(out, hello["ports"]), keep)


def _is_fifo(path) -> bool:
    try:
        return stat.S_ISFIFO(os.stat(path).st_mode)
    except OSError:
        return False


def _write(tap: TapClient, cap: Capture, keep: set[str] | None) -> bool:
    """Each record of *tap* that *keep* keeps into *cap*, flushed; whether the run ended."""
    hello = tap.hello
    cap.flush()  # Wireshark reads the section header at once
    for record in tap.records():
        if keep is not None and record.name not in keep:
            continue
        if record.kind == STREAM:
            stream = hello["streams"][record.name]
            cap.stream(record.name, stream["linktype"], stream.get("doc", ""),
                       record.t_device_ns, record.data)
        elif record.direction is not None:
            cap.chunk(record.name, record.t_device_ns, record.data, record.direction)
        else:
            continue
        cap.flush()
    return tap.ended


def extcap_folder() -> Path:
    """Wireshark's personal extcap folder, as this machine's tshark says (``tshark -G
    folders``: "Personal Extcap path", Wireshark 4.1 on; before, the personal configuration
    folder's ``extcap``); without tshark, ``$XDG_CONFIG_HOME/wireshark/extcap`` (4.0)."""
    tshark = shutil.which("tshark")
    if tshark is not None:
        try:
            out = subprocess.run([tshark, "-G", "folders"], capture_output=True, text=True,
                                 timeout=30).stdout
        except (OSError, subprocess.TimeoutExpired):
            out = ""
        folders = dict(line.split(":", 1) for line in out.splitlines() if ":" in line)
        folders = {k.strip(): v.strip() for k, v in folders.items()}
        if folders.get("Personal Extcap path"):
            return Path(folders["Personal Extcap path"])
        if folders.get("Personal configuration"):
            return Path(folders["Personal configuration"]) / "extcap"
    config_home = os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config"
    return Path(config_home) / "wireshark" / "extcap"


def install(folder: str | os.PathLike | None = None) -> Path:
    """Put the wrapper that runs ``navtwin extcap`` with this Python into *folder* (default
    :func:`extcap_folder`); its path."""
    target = Path(folder) if folder else extcap_folder()
    try:
        target.mkdir(parents=True, exist_ok=True)
        path = target / WRAPPER
        path.write_text(f"#!/bin/sh\n# navtwin's Wireshark extcap (navtwin extcap --install)\n"
                        f"exec {shlex.quote(sys.executable)} -m navtwin extcap \"$@\"\n")
        path.chmod(path.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    except OSError as e:
        raise ExtcapError(f"install: {target}: {e.strerror or e}; pass a folder you can "
                          "write (Wireshark's About > Folders lists its extcap folders)") from None
    return path
