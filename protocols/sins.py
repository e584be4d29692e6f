"""The SINS board frame: ADIS16350 register words over RS-232 (wire-formats.md section 1).

| offset | size | field | value                                                   |
|--------|------|-------|---------------------------------------------------------|
| 0      | 2    | sync  | ``A5 5A``                                               |
| 2      | 1    | type  | ``01`` = sample (others reserved, skipped by ``len``)   |
| 3      | 1    | len   | ``18`` (24) for type 01                                 |
| 4      | 2    | seq   | sample counter, +1 per sample, 65535 wraps to 0         |
| 6      | 22   | words | 11 raw register words, SUPPLY_OUT .. AUX_ADC            |
| 28     | 2    | crc   | CRC-16/CCITT-FALSE over bytes 2..27                      |

30 bytes, 2.604 ms on the wire at 115200 8N1; one frame every 10 ms of the board's clock.
"""
from construct import Array, Int16ub, Struct, Terminated

from .crcframe import crc_framed, encode
from .fast import packer_for

SYNC = b"\xa5\x5a"
TYPE_SAMPLE = 0x01
FRAME_SIZE = 30
PERIOD_S = 0.01
SEQ_MODULO = 1 << 16

Sample = Struct(
    "seq" / Int16ub,
    "words" / Array(11, Int16ub),
    Terminated,
)

SinsFrame = crc_framed(SYNC, {TYPE_SAMPLE: Sample})


_pack_sample = packer_for(Sample)


def build_sample(seq: int, words) -> bytes:
    """The 30-byte frame for one sample (fast path; equal to ``SinsFrame.build``)."""
    return encode(SYNC, TYPE_SAMPLE, _pack_sample(seq % SEQ_MODULO, *words))
