"""A cassette test (docs/testing.md, "A cassette test"): the host code under test asks the
coordinator for its API mode; recorded once against the lab with ``pytest --navtwin-record``
(the cassette is ``cassettes/test_the_host_reads_the_api_mode/`` beside this file), replayed
with no emulator process by ``pytest docs/examples/`` and by tests/test_docs.py."""
import serial

from navtwin.protocols import xbee
from navtwin.protocols.stream import XBeeDecoder
from navtwin.protocols.xbee import AtStatus, FrameType


def read_api_mode(port: str) -> int:
    """The host code under test: an AT query ``AP`` and the coordinator's answer to it."""
    decoder = XBeeDecoder(escaped=True)
    with serial.Serial(port, 115200, timeout=10) as ser:
        ser.write(xbee.build(FrameType.AT_COMMAND, frame_id=7, command=b"AP", parameter=b""))
        while True:
            chunk = ser.read(256)
            assert chunk, "the coordinator did not answer"
            for frame in decoder.feed(chunk):
                if getattr(frame, "type", None) == FrameType.AT_RESPONSE:
                    assert frame.fields["status"] == AtStatus.OK
                    return frame.fields["value"][0]


def test_the_host_reads_the_api_mode(navtwin_cassette):
    ports = navtwin_cassette("office", seed=1)
    assert read_api_mode(ports["xbee"]) == 2
