"""Fuzz target: the XBee decoder in API mode 1 (protocols.stream.XBeeDecoder(escaped=False))."""
from .xbee import target

SEEDS, check = target(escaped=False)
