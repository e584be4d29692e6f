"""CRC-16/CCITT-FALSE, the integrity check of the SINS frame and the nanoLOC report.

Poly 0x1021, init 0xFFFF, no reflection, xorout 0 (check value ``crc16(b"123456789") == 0x29B1``).
``binascii.crc_hqx`` is exactly this CRC with a caller-chosen init, implemented in C.

A frame's check: the CRC of the covered bytes followed by their CRC (big-endian) is 0, and
only then: appending two bytes t maps the register c to (c ^ t) * x^16 mod the polynomial,
which is 0 iff t == c (x^16 is invertible mod a polynomial with a constant term, and there
is no xorout). One C call and no compare, what a decoder does per frame.
"""
from binascii import crc_hqx

import numpy as np

CRC16_INIT = 0xFFFF


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of *data*."""
    return crc_hqx(data, CRC16_INIT)


_BITS = (np.arange(256)[:, None] >> np.arange(8)) & 1 == 1  # (value, bit): the bit is set


class RowsCrc:
    """A CRC of many messages of one length at once, as numpy columns, from the CRC of one
    message (*crc*: bytes -> int, a CRC-16: any polynomial, reflected or not, any init).

    A CRC register is linear over GF(2) in the message bits, plus a constant the init adds:
    crc(M) = crc(0^L) ^ XOR_j c_j(M_j) over the L bytes, where c_j(v) is what byte value v at
    position j adds. Started from a zero register, leading zero bytes leave it zero, so c_j
    depends only on how many bytes follow j (d = L - 1 - j): c(v, d) = crc(v 0^d) ^ crc(0^(d+1)).
    A table of 256 entries per d (made from *crc* itself, as far as the longest length used) turns
    the CRCs of n rows into one lookup of every (row, column) byte and one XOR across the
    columns: two numpy calls for a block, not one call per frame.
    """

    def __init__(self, crc) -> None:
        self.crc = crc
        self._by_d = np.empty((0, 256), dtype=np.uint16)  # row d: c(v, d)
        self._lengths: dict[int, tuple[np.ndarray, int]] = {}  # L: (tables by column, crc(0^L))

    def _tables(self, length: int) -> tuple[np.ndarray, int]:
        if length not in self._lengths:
            # c(v, d) is linear in v too: the XOR of c(2^b, d) over v's set bits b, so eight
            # calls of the CRC a distance make its 256 entries
            basis = np.array([[self.crc(bytes((1 << b,)) + bytes(d)) ^ self.crc(bytes(d + 1))
                               for b in range(8)] for d in range(len(self._by_d), length)],
                             dtype=np.uint16).reshape(-1, 1, 8)
            self._by_d = np.concatenate((self._by_d, np.bitwise_xor.reduce(
                np.where(_BITS, basis, np.uint16(0)), axis=2)))
            self._lengths[length] = (self._by_d[length - 1::-1] if length else self._by_d[:0],
                                     self.crc(bytes(length)))
        return self._lengths[length]

    def __call__(self, rows: np.ndarray) -> np.ndarray:
        """The CRC of each row of *rows* ((n, L) uint8) as an (n,) uint16 array."""
        n, length = rows.shape
        tables, zero = self._tables(length)
        if not length:
            return np.full(n, zero, dtype=np.uint16)
        return np.bitwise_xor.reduce(tables[np.arange(length), rows], axis=1) ^ np.uint16(zero)


#: :func:`crc16` of every row of an (n, L) uint8 array
crc16_rows = RowsCrc(crc16)
