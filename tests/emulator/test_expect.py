"""lab.expect / expect_none / idle (emulator.expect) on live labs, in real and virtual time.

Every wait is on the port's data with a deadline; the generous ones (DEADLINE_S) are for
events that must come, the short ones are the windows under test."""
import json
import re
import time

import pytest

from navtwin.emulator.api import ExpectTimeout, Unexpected, emulate
from navtwin.protocols import xbee

from ..helpers import DEADLINE_S, navtwin, one_line_error

pytestmark = pytest.mark.pty


@pytest.fixture(scope="module")
def office():
    with emulate("office", seed=3, speed="realtime", ready_timeout=DEADLINE_S) as lab:
        yield lab


def test_expect_a_sins_frame_by_predicate_in_real_time(office):
    f = office.expect("sins", lambda f: f.seq >= 20, timeout=DEADLINE_S)
    assert f.format == "sins" and f.seq >= 20 and len(f.words) == 11
    assert set(f.record) >= {"seq", "gyro_dps", "accel_g"}  # engineering units as decode gives
    later = office.expect("sins", lambda f: True, timeout=DEADLINE_S)
    assert later.seq == f.seq + 1  # the stream is consumed up to the match, no further


def test_expect_bytes_and_a_regex_on_the_raw_stream(office):
    start = office.expect("xbee", bytes([xbee.START]), timeout=DEADLINE_S)
    assert start.group(0) == b"\x7e"
    found = office.expect("xbee", re.compile(rb"\x7e\x00.\x90", re.S), timeout=DEADLINE_S)
    assert found.group(0)[-1] == 0x90  # a receive packet's header


def test_a_predicate_on_the_coordinators_frames(office):
    # the xbee port decodes as its declared format: XBee frames and the SINS frames within
    f = office.expect("xbee", lambda f: f.format == "sins" and f.seq > 5, timeout=DEADLINE_S)
    assert f.source is not None  # the router's address


def test_expect_timeout_says_what_where_how_long_and_the_last_frames(office):
    t = time.monotonic()
    with pytest.raises(ExpectTimeout) as e:
        office.expect("sins", lambda f: f.seq < 0, timeout=0.5)
    assert time.monotonic() - t >= 0.5
    msg = str(e.value)
    assert msg.startswith("lab.expect: nothing matching a frame for which <lambda>")
    assert "f.seq < 0" in msg and "port 'sins'" in msg and "within 0.5 s" in msg
    assert "wall time (real-time lab)" in msg and "last frames decoded:" in msg
    frames = msg.split("last frames decoded:\n")[1].splitlines()
    assert len(frames) == 8 and all("format=sins" in f and "gyro_dps=[" in f for f in frames)
    assert isinstance(e.value, AssertionError)


def test_expect_none_passes_when_nothing_matches_and_fails_when_it_does(office):
    office.expect_none("nanoloc", b"no such bytes", within=1.0)
    with pytest.raises(Unexpected) as e:
        office.expect_none("sins", lambda f: f.seq % 10 == 0, within=DEADLINE_S)
    msg = str(e.value)
    assert "lab.expect_none: a frame for which <lambda>" in msg and "port 'sins'" in msg
    assert re.search(r"came on port 'sins' within the 120 s window: format=sins .*seq=\d*0 ", msg)


def test_idle_fails_on_an_active_port_and_passes_on_an_unplugged_one():
    with emulate("office", seed=3, speed="realtime", ready_timeout=DEADLINE_S) as lab:
        with pytest.raises(Unexpected, match=r"lab.idle: port 'sins' was not idle for 120 s: "
                                             r"\d+ bytes came"):
            lab.idle("sins", DEADLINE_S)
        lab.unplug("sins")
        lab.idle("sins", 1.0)
        lab.replug("sins")  # the link is back: expect opens the new PTY behind it
        assert lab.expect("sins", lambda f: True, timeout=DEADLINE_S).format == "sins"


def test_in_virtual_time_timeouts_are_device_time():
    with emulate("office", seed=3, speed=4, ready_timeout=DEADLINE_S) as lab:
        lab.expect("sins", lambda f: f.seq >= 100, timeout=DEADLINE_S)
        t = time.monotonic()
        with pytest.raises(ExpectTimeout) as e:
            lab.expect("sins", lambda f: f.seq < 0, timeout=4.0)
        assert time.monotonic() - t < 3.5  # 4 device s at 4x: about 1 s of wall time
        assert "s device time" in str(e.value) and "lab at speed 4" in str(e.value)


def test_at_max_speed_expect_waits_on_the_data():
    with emulate("office", seed=3, speed="max", ready_timeout=DEADLINE_S) as lab:
        # >=: at max the lab does not wait for a slow reader (its overflow drops, docs/emulator.md)
        f = lab.expect("sins", lambda f: f.seq >= 3000, timeout=60)  # 30 s of device time
        assert 3000 <= f.seq < 3000 + 2000
        with pytest.raises(ExpectTimeout, match=r"device time .*lab at speed max"):
            lab.expect("sins", b"no such bytes", timeout=2.0)


def test_bad_matches_and_ports_are_one_line_errors(office):
    with pytest.raises(TypeError, match="is on str; compile it on bytes"):
        office.expect("sins", re.compile("x"), timeout=1)
    with pytest.raises(TypeError, match="int is not bytes, a compiled regex or a predicate"):
        office.expect("sins", 5, timeout=1)
    with pytest.raises(ValueError, match="the lab has no port 'gps'; use one of sins, xbee"):
        office.expect("gps", b"x", timeout=1)


def test_a_board_reset_seen_by_expect(office):
    """The plugin's docstring example: the counter starts again after a reset."""
    office.expect("sins", lambda f: f.seq >= 200, timeout=DEADLINE_S)
    office.reset("board")
    assert office.expect("sins", lambda f: f.seq < 5, timeout=DEADLINE_S).seq < 5


# -- navtwin emulate --expect / --fail-on / --timeout: shell CI ----------------------------------
def _emulate(tmp_path, *args, speed="max"):
    return navtwin("emulate", "--scenario", "office", "--speed", speed, "--quiet",
                   "--link-dir", tmp_path / "links", *args)


def test_cli_expects_met_stop_the_run_with_status_0(tmp_path):
    r = _emulate(tmp_path, "--expect", "sins:seq=300", "--expect", "sins:seq=310",
                 "--expect", "nanoloc:anchor=2,status=0x0F", "--expect", "xbee:re:\\x7e",
                 "--timeout", "30", speed="20")  # paced: no frame dropped for a slow reader
    assert r.returncode == 0, r.stderr
    done = json.loads(r.stdout.splitlines()[-1])
    assert done["interrupted"] and done["virtual_s"] < 70  # stopped once all had come


def test_cli_expect_timeout_is_status_3_with_the_last_frames(tmp_path):
    r = _emulate(tmp_path, "--expect", "sins:seq=65000", "--timeout", "3")
    assert r.returncode == 3
    assert json.loads(r.stdout.splitlines()[-1])["done"]
    head, frames = r.stderr.split("last frames decoded:\n")
    assert head.startswith("navtwin emulate: --expect: nothing matching a frame with seq=65000 "
                           "on port 'sins' within 3 s after ")
    assert "s device time" in head and "lab at speed max" in head
    assert all("format=sins" in f and "accel_g=[" in f for f in frames.splitlines())


def test_cli_fail_on_is_status_3_and_passes_when_absent(tmp_path):
    r = _emulate(tmp_path, "--fail-on", "nanoloc:anchor=3", "--timeout", "10")
    assert r.returncode == 3
    assert re.match(r"navtwin emulate: --fail-on: a frame with anchor=3 came on port 'nanoloc': "
                    r"format=nanoloc .*anchor=3 ", r.stderr)
    r = _emulate(tmp_path, "--fail-on", "nanoloc:anchor=9", "--timeout", "3")
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("args, words", [
    (["--expect", "gps:hex:7E"], ["--expect", "PORT one of sins, xbee, nanoloc"]),
    (["--expect", "sins:hex:7G"], ["--expect", "is not hex bytes"]),
    (["--fail-on", "sins:re:("], ["--fail-on", "not a byte regex"]),
    (["--expect", "sins:seq"], ["--expect", "FIELD=VALUE"]),
    (["--timeout", "3"], ["--timeout bounds --expect/--fail-on"]),
])
def test_cli_bad_expectations_are_one_line_errors(tmp_path, args, words):
    one_line_error(_emulate(tmp_path, *args), *words)
