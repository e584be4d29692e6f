"""navtwin: a firmware-in-the-loop emulator of a SINS/WSN positioning lab and the lab
computer's fusion service, in one namespace (docs/architecture.md): navtwin.protocols,
navtwin.common, navtwin.emulator, navtwin.host, navtwin.lab and navtwin.cli."""
from .protocols import __version__

__all__ = ["__version__"]
