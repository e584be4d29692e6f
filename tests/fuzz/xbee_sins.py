"""Fuzz target: the coordinator port's chain, XBee API frames -> SINS frames of each source
(protocols.stream.XBeeSinsChain), in API mode 1 or 2 as the input chooses."""
from navtwin.protocols import sins, xbee
from navtwin.protocols.stream import Frame, XBeeDecoder, XBeeSinsChain

from .harness import Input, assert_recovered, feed, framed, split
from .sins import BOUND as SINS_BOUND
from .sins import TAIL as SINS_TAIL
from .xbee import ROUTER, bound, golden

#: few, so that the inputs reach the eviction of the least recently heard source often
SOURCES = 4
API1, API2 = b"\x00\x00", b"\x00\x01"  # the input's last two bytes choose the API mode
SEEDS = [golden(True) + API2, golden(False) + API1,
         golden(True)[:300] + sins.build_sample(1, [0] * 11)[:17] + golden(True)[300:500] + API2]


def tail(escaped: bool) -> list[bytes]:
    """0x90 packets from the router, one SINS frame in each."""
    return [xbee.build(xbee.FrameType.RECEIVE_PACKET, escaped, src64=ROUTER, src16=0xFFFE,
                       options=1, data=s) for s in SINS_TAIL]


def check(data: bytes) -> None:
    """The decoder contracts (harness.check_decoder) for both layers: the XBee decoder's
    buffer and every SINS stream's stay bounded, at most SOURCES streams, the same events in
    any chunking, and the SINS frames in packets appended after the input are recovered."""
    inp = Input(data)
    escaped = inp.int(2) == 1
    chunks = split(inp)
    stream = inp.rest()
    most = bound(escaped)

    def bounded(chain, chunk):
        assert chain.xbee.buffered <= most + chunk
        assert len(chain.sins) <= SOURCES
        # a SINS stream is fed the payloads of what the XBee layer held and the chunk gave
        assert all(d.buffered <= SINS_BOUND + most + chunk for d in chain.sins.values())

    def make():
        return XBeeSinsChain(escaped, max_sources=SOURCES)

    whole = feed(make(), [stream], bounded)
    assert feed(make(), chunks(stream), bounded) == whole, "another chunking, other events"

    packets = tail(escaped)
    full = stream + b"".join(packets)
    expected = framed(len(stream), packets)
    xbee_events = XBeeDecoder(escaped).decode(full)
    assert_recovered(xbee_events, expected, lossless=escaped)
    if not set(expected) <= {(e.offset, e.raw) for e in xbee_events if isinstance(e, Frame)}:
        return  # a false candidate in the garbage took a packet (API mode 1, stream.py)
    chain = make()
    router = [e for e in chain.decode(full) if e.source == ROUTER and e.format == "sins"]
    start = chain.sins[ROUTER].bytes - sum(map(len, SINS_TAIL))
    assert_recovered(router, framed(start, SINS_TAIL), lossless=False)
