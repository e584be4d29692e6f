"""Fuzz target: the SINS decoder (protocols.stream.sins_decoder)."""
from navtwin.protocols import crcframe, sins
from navtwin.protocols.stream import sins_decoder

from .harness import check_decoder, fixture

#: valid frames appended after each input: two samples and one of a type SINS does not declare
TAIL = [sins.build_sample(7, [0x8000 + i for i in range(11)]),
        crcframe.encode(sins.SYNC, 0x33, b"a type of its own"),
        sins.build_sample(0xFFFF, [0xA55A] * 11)]
BOUND = crcframe.HEADER + 0xFF + crcframe.TRAILER  # the longest candidate a length can claim
SEEDS = [b"".join(TAIL), fixture("golden", "office", "sins.bin", size=600),
         TAIL[0][:-1] + b"\x00" + TAIL[1][:9]]


def check(data: bytes) -> None:
    check_decoder(sins_decoder, data, bound=BOUND, tail=TAIL, lossless=False)
