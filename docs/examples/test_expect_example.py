"""A user's integration test with expect (docs/testing.md, "A user's integration test with
expect"): the test waits on the lab's frames with deadlines, never sleeps and counts.
``pytest docs/examples/`` runs it; tests/test_docs.py runs it with the suite."""
import serial

from navtwin.protocols import nanoloc, xbee
from navtwin.protocols.xbee import AtStatus, FrameType

TIMEOUT_S = 20.0  # generous: the box may be loaded (device time when --navtwin-speed max)


def test_the_coordinator_answers_an_at_query(navtwin_office):
    lab = navtwin_office
    with serial.Serial(lab.ports["xbee"], 115200) as ser:  # the host code under test writes
        ser.write(xbee.build(FrameType.AT_COMMAND, frame_id=7, command=b"AP", parameter=b""))
        # ... and the lab's coordinator answers it: an AT response, frame 7, status OK
        ok = lab.expect("xbee", lambda f: f.type == FrameType.AT_RESPONSE and f.frame_id == 7,
                        timeout=TIMEOUT_S)
    assert ok.command == b"AP" and ok.status == AtStatus.OK and ok.value == b"\x02"


def test_an_anchor_outage_times_out_that_anchor_and_ends(navtwin_lab):
    lab = navtwin_lab("office", seed=3)
    lab.expect("nanoloc", lambda f: nanoloc.is_complete(f.status), timeout=TIMEOUT_S)
    lab.fault("anchor_outage", 2.0, anchor=1)
    lab.expect("nanoloc", lambda f: f.anchor == 1 and f.status == nanoloc.STATUS_TIMEOUT,
               timeout=TIMEOUT_S)
    # the other anchors keep ranging through the outage ...
    lab.expect_none("nanoloc", lambda f: f.anchor != 1 and not nanoloc.is_complete(f.status),
                    within=1.0)
    # ... and anchor 1 is back once it is over
    lab.expect("nanoloc", lambda f: f.anchor == 1 and nanoloc.is_complete(f.status),
               timeout=TIMEOUT_S)


def test_a_pulled_cable_is_silence(navtwin_office):
    navtwin_office.expect("sins", lambda f: f.seq >= 100, timeout=TIMEOUT_S)
    navtwin_office.unplug("sins")
    navtwin_office.idle("sins", 1.0)
