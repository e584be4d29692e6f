"""CRC-16/CCITT-FALSE, the integrity check of the SINS frame and the nanoLOC report.

Poly 0x1021, init 0xFFFF, no reflection, xorout 0 (check value ``crc16(b"123456789") == 0x29B1``).
``binascii.crc_hqx`` is exactly this CRC with a caller-chosen init, implemented in C.

A frame's check: the CRC of the covered bytes followed by their CRC (big-endian) is 0, and
only then: appending two bytes t maps the register c to (c ^ t) * x^16 mod the polynomial,
which is 0 iff t == c (x^16 is invertible mod a polynomial with a constant term, and there
is no xorout). One C call and no compare, what a decoder does per frame.
"""
from binascii import crc_hqx

CRC16_INIT = 0xFFFF


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of *data*."""
    return crc_hqx(data, CRC16_INIT)
