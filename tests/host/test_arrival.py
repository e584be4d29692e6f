"""The arrival rule shared by replay of an emulator recording and the in-memory run."""
from navtwin.host.arrival import arrivals
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
