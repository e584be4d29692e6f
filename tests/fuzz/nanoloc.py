"""Fuzz target: the nanoLOC gateway decoder (protocols.stream.nanoloc_decoder)."""
from navtwin.protocols import crcframe, nanoloc
from navtwin.protocols.stream import nanoloc_decoder

from .harness import check_decoder, fixture

#: valid frames appended after each input: two reports, a wide one (type 02) and one of an
#: undeclared type
TAIL = [nanoloc.build_report(seq=7, t_us=123456, anchor=1, tag=16, status=0x0F, rssi=-60,
                             tau=[99902284, 99999999, 99902284, 99999999]),
        nanoloc.build_report(seq=8, t_us=1123456, anchor=1001, tag=1000, status=0x0F, rssi=-60,
                             tau=[99902284, 99999999, 99902284, 99999999], wide=True),
        crcframe.encode(nanoloc.SYNC, 0x03, b"NL"),
        nanoloc.build_report(seq=0xFFFF, t_us=0xFFFFFFFF, anchor=254, tag=1, status=0x80,
                             rssi=-128, tau=[0x4E4C] * 4)]
BOUND = crcframe.HEADER + 0xFF + crcframe.TRAILER
SEEDS = [b"".join(TAIL), fixture("golden", "office", "nanoloc.bin", size=600),
         fixture("golden", "outage-bridging", "nanoloc.bin", size=600), TAIL[0][:20] + TAIL[3]]


def check(data: bytes) -> None:
    check_decoder(nanoloc_decoder, data, bound=BOUND, tail=TAIL, lossless=False)
