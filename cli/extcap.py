"""``navtwin extcap``: a running lab as a Wireshark capture interface (emulator.extcap)."""
from __future__ import annotations

from navtwin.protocols.linkdir import default_link_dir

from .main import UsageError

DESCRIPTION = """\
Wireshark's extcap interface to a running lab: `navtwin extcap --install` puts a wrapper in
Wireshark's personal extcap folder (it prints where); Wireshark then lists the interface
"navtwin" and, when you start it, streams every port of the lab on its link directory (the
interface's option; default: the one `navtwin emulate` uses) as it happens, one Wireshark
interface per port, both directions, stamped with device time, until the lab ends or you stop
it. The other options are the extcap protocol's, which Wireshark passes (docs/testing.md,
"Live in Wireshark"). Without a lab on the link directory: one line, exit status 2."""


def register(sub) -> None:
    p = sub.add_parser("extcap", help="a running lab as a Wireshark capture interface",
                       description=DESCRIPTION)
    p.add_argument("--install", nargs="?", const="", metavar="FOLDER",
                   help="put the extcap wrapper into FOLDER (default: Wireshark's personal "
                        "extcap folder, as `tshark -G folders` says) and print its path")
    p.add_argument("--extcap-interfaces", action="store_true",
                   help="list the interface (extcap protocol)")
    p.add_argument("--extcap-version", nargs="?", const="", default=None, metavar="VERSION",
                   help="print navtwin's extcap version; Wireshark passes its own")
    p.add_argument("--extcap-interface", metavar="NAME", help="the interface: navtwin")
    p.add_argument("--extcap-dlts", action="store_true", help="the interface's link type")
    p.add_argument("--extcap-config", action="store_true", help="the interface's options")
    p.add_argument("--capture", action="store_true", help="capture into --fifo")
    p.add_argument("--fifo", metavar="PATH", help="where the pcapng goes (Wireshark's FIFO, "
                                                  "or a file)")
    p.add_argument("--extcap-capture-filter", metavar="NAMES",
                   help="the ports (and streams) to keep, e.g. \"sins xbee\" (default: all)")
    p.add_argument("--link-dir", metavar="DIR", default=None,
                   help=f"the lab's link directory (default: {default_link_dir()})")
    p.set_defaults(func=run_extcap)


def run_extcap(args) -> int:
    import sys

    from navtwin.emulator import extcap
    from navtwin.emulator.tap import TapError

    try:
        if args.install is not None:
            print(f"installed {extcap.install(args.install or None)}; restart Wireshark and "
                  f"pick the interface {extcap.INTERFACE}")
            return 0
        if args.extcap_interfaces or (args.extcap_version is not None
                                      and args.extcap_interface is None):
            lines = extcap.interfaces()
            print("\n".join(lines if args.extcap_interfaces else lines[:1]))
            return 0
        if args.extcap_dlts:
            print("\n".join(extcap.dlts(args.extcap_interface)))
            return 0
        if args.extcap_config:
            print("\n".join(extcap.config(args.extcap_interface)))
            return 0
        keep = extcap.selection(args.extcap_capture_filter)
        if not args.capture:
            if args.extcap_capture_filter is not None:
                return 0  # Wireshark validating a filter: its names are checked at capture
            raise UsageError("say what to do: --extcap-interfaces, --extcap-dlts, "
                             "--extcap-config, --capture --fifo PATH, or --install")
        if args.fifo is None:
            raise UsageError("--capture needs --fifo PATH (Wireshark passes it)")
        extcap.check_interface(args.extcap_interface or extcap.INTERFACE)
        link_dir = args.link_dir or default_link_dir()
        try:
            ended = extcap.capture(link_dir, args.fifo, keep)
        except BrokenPipeError:
            return 0  # the reader closed the FIFO: Wireshark stopped the capture
        if not ended:
            print("navtwin extcap: the lab closed its tap before the run's end: this capture "
                  "fell behind and was dropped, or the lab stopped abnormally",
                  file=sys.stderr)
            return 1
        return 0
    except (extcap.ExtcapError, TapError) as e:
        raise UsageError(str(e)) from None
