"""navtwin wire formats: the SINS board frame, XBee API frames and the nanoLOC report.

Declared once with construct (``sins``, ``xbee``, ``nanoloc``), decoded from streams by
``stream``, recorded and replayed by ``recording``. This package imports nothing else of
navtwin's: the emulator and the host both build on it.
"""
__version__ = "0.1.0"
