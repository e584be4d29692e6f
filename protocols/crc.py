"""CRC-16/CCITT-FALSE, the integrity check of the SINS frame and the nanoLOC report.

Poly 0x1021, init 0xFFFF, no reflection, xorout 0 (check value ``crc16(b"123456789") == 0x29B1``).
``binascii.crc_hqx`` is exactly this CRC with a caller-chosen init, implemented in C.
"""
from binascii import crc_hqx

CRC16_INIT = 0xFFFF


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of *data*."""
    return crc_hqx(data, CRC16_INIT)
