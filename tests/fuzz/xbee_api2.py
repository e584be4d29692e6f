"""Fuzz target: the XBee decoder in API mode 2 (protocols.stream.XBeeDecoder(escaped=True))."""
from .xbee import target

SEEDS, check = target(escaped=True)
