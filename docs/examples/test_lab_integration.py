"""Integration tests of the kind a lab user writes against the emulated lab (docs/tutorial.md,
step 6). The fixtures come from navtwin's pytest plugin, installed with navtwin:
``pytest docs/examples/`` runs them, and tests/test_docs.py runs them with the suite."""
import time

import serial

from navtwin.protocols.decode import frame_record
from navtwin.protocols.nanoloc import STATUS_TIMEOUT
from navtwin.protocols.stream import Frame, nanoloc_decoder, sins_decoder

DEADLINE_S = 20.0  # generous: the box may be loaded; a test waits on data, never on a sleep


def read_frames(port, decoder, enough):
    """The frames decoded from *port*, as ``navtwin decode`` prints them (dicts with
    engineering units), until ``enough(frames)`` holds; fails at the deadline."""
    frames = []
    end = time.monotonic() + DEADLINE_S
    with serial.Serial(port, 115200, timeout=0.5) as ser:
        while not enough(frames):
            assert time.monotonic() < end, f"only {len(frames)} frames in {DEADLINE_S:g} s"
            frames += [frame_record(e) for e in decoder.feed(ser.read(ser.in_waiting or 1))
                       if isinstance(e, Frame)]
    return frames


def test_the_sins_board_sends_consecutive_samples_of_one_g(navtwin_office):
    frames = read_frames(navtwin_office.ports["sins"], sins_decoder(), lambda f: len(f) >= 100)
    seqs = [f["seq"] for f in frames]
    assert all((b - a) % 65536 == 1 for a, b in zip(seqs, seqs[1:]))  # no sample lost
    z = [f["accel_g"][2] for f in frames]
    assert abs(sum(z) / len(z) - 1.0) < 0.05  # the vehicle drives on a level floor


def test_an_anchor_outage_times_out_that_anchor_only(navtwin_lab):
    lab = navtwin_lab("office", seed=3)
    outage = lab.fault("anchor_outage", 2.0, anchor=1)  # starts with the world's next block
    start_us, end_us = outage["start_s"] * 1e6, outage["end_s"] * 1e6
    frames = read_frames(lab.ports["nanoloc"], nanoloc_decoder(),
                         lambda f: f and f[-1]["t_us"] > end_us + 0.5e6)
    # 0.1 s margins: t_us is the gateway's clock, which drifts from the emulator's
    during = [f for f in frames if start_us + 1e5 < f["t_us"] < end_us - 1e5]
    assert {r["anchor"] for r in during} == {1, 2, 3, 4}
    for r in during:
        assert (r["status"] == STATUS_TIMEOUT) == (r["anchor"] == 1), r
    after = [f for f in frames if f["t_us"] > end_us + 1e5]
    assert after and all(r["complete"] for r in after)
