"""The lines keep up with the wide sample frame (type 03, 42 bytes every 10 ms): measured on
rssi-centroid's golden recording (10 s, seed 3, the magnetometer's 10 Hz frames interleaved),
the figures docs/protocols.md ("Wide sample frame") quotes."""
import numpy as np
import pytest

from navtwin.protocols import sins
from navtwin.protocols.recording import Recording
from navtwin.protocols.serial import char_ns
from navtwin.protocols.stream import Frame, XBeeSinsChain, sins_decoder

BAUD = 115200


def first_seen(rec: Recording, port: str, decoder) -> dict[int, int]:
    """seq -> device time of the chunk that completed each sample frame on *port*."""
    out: dict[int, int] = {}
    for c in rec.chunks(port):
        for e in decoder.feed(c.data):
            if isinstance(e, Frame) and e.type in sins.SAMPLE_TYPES:
                out.setdefault(e.fields["seq"], c.t_device_ns)
    return out


@pytest.fixture(scope="module")
def golden(root):
    return Recording(root / "fixtures" / "golden" / "rssi-centroid")


def occupancy(rec: Recording, port: str) -> float:
    return len(rec.read_bytes(port)) * char_ns(BAUD) / (rec.meta["duration_s"] * 1e9)


def test_the_board_line_is_37_7_percent_busy(golden):
    # 100 wide frames and 10 magnetometer frames a second; type 01 frames would be 27.3 %
    assert occupancy(golden, "sins") == pytest.approx((100 * 42 + 10 * 14) * 10 / BAUD)
    assert (100 * 30 + 10 * 14) * 10 / BAUD == pytest.approx(0.273, abs=5e-4)
    assert occupancy(golden, "sins") == pytest.approx(0.377, abs=5e-4)


def test_the_radio_and_the_coordinator_keep_up(golden):
    """Every sample crosses the radio with a steady latency (no queue builds up) and the
    coordinator's 0x90 frames take about half its line."""
    board = first_seen(golden, "sins", sins_decoder())
    radio = first_seen(golden, "xbee", XBeeSinsChain())
    assert len(board) == 1000 and len(radio) >= 995 and set(radio) <= set(board)
    lat = np.array([radio[k] - board[k] for k in sorted(radio)]) / 1e6  # ms
    assert np.median(lat) == pytest.approx(10.6, abs=0.2)
    assert np.percentile(lat, 99) < 14.5 and lat.max() < 17.0
    assert abs(np.median(lat[-200:]) - np.median(lat[:200])) < 0.5  # no growing queue
    assert occupancy(golden, "xbee") == pytest.approx(0.53, abs=0.005)  # API 2 escapes vary
