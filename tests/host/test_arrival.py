"""The arrival rule shared by replay of an emulator recording and the in-memory run."""
import numpy as np

from navtwin.host.arrival import arrivals, processing_order
from navtwin.protocols.serial import wire_ns


def test_arrival_is_the_last_byte_off_the_uart_in_arrival_order():
    streams = {"nanoloc": [(b"N" * 32, 0)], "xbee": [(b"\x7e" * 6, 0), (b"\x7e" * 40, 10_000)]}
    got = list(arrivals(streams, {"xbee": 115200, "nanoloc": 115200}))
    assert [(p, t) for p, _, t in got] == [("xbee", wire_ns(6, 115200)),
                                           ("nanoloc", wire_ns(32, 115200)),
                                           ("xbee", 10_000 + wire_ns(40, 115200))]


def test_ties_follow_the_port_order_and_stamps_strictly_increase():
    streams = {"nanoloc": [(b"a", 0)], "sins": [(b"b", 0)], "xbee": [(b"c", 0), (b"d", 0)]}
    got = list(arrivals(streams, dict.fromkeys(streams, 115200)))
    assert [d for _, d, _ in got] == [b"c", b"d", b"b", b"a"]
    t = wire_ns(1, 115200)
    assert [s for _, _, s in got] == [t, t + 1, t + 2, t + 3]


def test_the_array_form_gives_the_same_order_and_stamps():
    """processing_order, the bulk path's form of the rule, on the cases above and on
    interleaved ports with ties."""
    cases = [{"nanoloc": [(b"N" * 32, 0)], "xbee": [(b"\x7e" * 6, 0), (b"\x7e" * 40, 10_000)]},
             {"nanoloc": [(b"a", 0)], "sins": [(b"b", 0)], "xbee": [(b"c", 0), (b"d", 0)]},
             {"xbee": [(b"x" * (5 + k % 7), 1_000_000 * k) for k in range(40)],
              "nanoloc": [(b"n" * 32, 2_000_000 * k) for k in range(20)]}]
    for streams in cases:
        bauds = dict.fromkeys(streams, 115200)
        arrays = {p: (b"".join(d for d, _ in c), np.array([len(d) for d, _ in c]),
                      np.array([t for _, t in c])) for p, c in streams.items()}
        at, stamp = processing_order(arrays, bauds)
        got = sorted((int(k), p, j) for p, pos in at.items() for j, k in enumerate(pos))
        want = list(arrivals(streams, bauds))
        assert [streams[p][j][0] for _, p, j in got] == [d for _, d, _ in want]
        assert stamp.tolist() == [s for _, _, s in want]
