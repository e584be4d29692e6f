"""The XBee API frames the two XBee targets (xbee_api1, xbee_api2) share: seeds and tails."""
from navtwin.protocols import sins, xbee
from navtwin.protocols.stream import Frame, XBeeDecoder

from .harness import check_decoder, fixture

ROUTER = 0x0013A20040A1B2D4  # the lab's router
#: what the coordinator's port carries, its data full of bytes API mode 2 escapes
FIELDS = [(xbee.FrameType.RECEIVE_PACKET, dict(src64=ROUTER, src16=0x7D11, options=1,
                                               data=sins.build_sample(0x7E7D, [0x1113] * 11))),
          (0x88, dict(frame_id=1, command=b"BD", status=0, value=b"\x00\x07")),
          (0x8A, dict(status=6)),
          (0x8B, dict(frame_id=0x7E, dest16=0xFFFE, retries=0, delivery=0, discovery=0)),
          (0xC5, dict(body=b"a type the format does not declare"))]


def tail(escaped: bool) -> list[bytes]:
    return [xbee.build(t, escaped, **f) for t, f in FIELDS]


def golden(escaped: bool, size: int = 700) -> bytes:
    """The start of the office golden's coordinator port (recorded in API mode 2)."""
    api2 = fixture("golden", "office", "xbee.bin", size=size)
    if escaped:
        return api2
    frames = [e for e in XBeeDecoder(escaped=True).decode(api2) if isinstance(e, Frame)]
    return b"".join(xbee.wrap(xbee.unescape(f.raw[1:])[2:-1], False) for f in frames)


def bound(escaped: bool) -> int:
    """The longest candidate a length can claim (escaped: every byte may be doubled)."""
    most = XBeeDecoder().max_frame_data + 4
    return 2 * most if escaped else most


def target(escaped: bool):
    """(SEEDS, check) of the XBee decoder in API mode 2 (*escaped*) or 1."""
    frames = tail(escaped)
    seeds = [b"".join(frames), golden(escaped), frames[0][:12] + frames[1] + b"\x7d" + frames[2]]

    def check(data: bytes) -> None:
        check_decoder(lambda: XBeeDecoder(escaped), data, bound=bound(escaped), tail=frames,
                      lossless=escaped)  # stream.py: in API mode 2 garbage cannot swallow a frame
    return seeds, check
