"""Fuzz target: the SINS decoder (protocols.stream.sins_decoder)."""
from navtwin.protocols import crcframe, sins
from navtwin.protocols.stream import sins_decoder

from .harness import check_decoder, fixture

#: valid frames appended after each input: two samples, the magnetometer frame read with the
#: first, one of a type SINS does not declare and a wide sample (type 03)
TAIL = [sins.build_sample(7, [0x8000 + i for i in range(11)]),
        sins.build_magnetometer(7, (230, -50, -480)),
        crcframe.encode(sins.SYNC, 0x33, b"a type of its own"),
        sins.build_sample(0xFFFF, [0xA55A] * 11),
        sins.build_wide_sample(8, 0x8AAA, (0, 32768, -1), (-(1 << 31), 0, 81920000), (0x8000,) * 3, 0xA55A)]
BOUND = crcframe.HEADER + 0xFF + crcframe.TRAILER  # the longest candidate a length can claim
#: a stream with the magnetometer on: samples and magnetometer frames interleaved, one of
#: them cut short, one overflowed, one claiming the sample's length
MAGNETOMETER = (sins.build_sample(10, [0x8000] * 11) + sins.build_magnetometer(10, (1, -2, 3))
                + sins.build_magnetometer(20, (-4096, 2047, -2048))[:9]
                + sins.build_sample(20, [0x8000] * 11) + sins.build_magnetometer(20, (-4096, 0, 0))
                + crcframe.encode(sins.SYNC, sins.TYPE_MAGNETOMETER, bytes(24)))
SEEDS = [b"".join(TAIL), fixture("golden", "office", "sins.bin", size=600),
         fixture("golden", "rssi-centroid", "sins.bin", size=600),  # wide samples and magnetometer
         TAIL[0][:-1] + b"\x00" + TAIL[1][:9], MAGNETOMETER]


def check(data: bytes) -> None:
    check_decoder(sins_decoder, data, bound=BOUND, tail=TAIL, lossless=False)
