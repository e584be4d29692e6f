"""The host's pipeline beside the emulator's coordinator, in memory: what one side does to the
XBee's API mode, the other sees."""
from navtwin.emulator.runner import SEC, Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.host.pipeline import DB_PERIOD_S, Pipeline
from navtwin.protocols import xbee

from ..helpers import OFFICE
from ..host.fake_estimator import RecordingEstimator


def test_a_second_clients_atap1_is_seen_by_an_api2_host():
    """Issue 7 point 9, with the emulator's coordinator in memory: a second client sends ATAP1
    at 3 s (and reads the OK itself); the host learns it from its own periodic AP query and
    says so; the second client's ATAP2 at 12 s puts things right, and the host says that."""
    emu = Emulation(load_scenario("office"), speed=None, ports=False, duration_s=20)
    coord, line = emu.coordinators["xbee"], emu.lines["xbee"]
    second = {3 * SEC: xbee.build(0x08, True, frame_id=0x42, command=b"AP", parameter=b"\x01"),
              12 * SEC: xbee.build(0x08, False, frame_id=0x43, command=b"AP", parameter=b"\x02")}
    pipe = Pipeline(OFFICE, make_estimator=lambda _: RecordingEstimator(), inputs=("xbee",))
    events, t, step = [], 0, 1_000_000
    while t < emu.end_ns:
        t += step
        emu._enqueue(emu.world.advance(t))
        for out in coord.host(t, second.pop(t, b"")):
            line.put(out.t_ns, out.item)
        for chunk in line.poll(t, t, emu.end_ns):
            if chunk.data[4:5] in (b"\x42", b"\x43") and chunk.data[3] == 0x88:
                continue  # the second client's answers: it reads them, not the host
            pipe.feed("xbee", chunk.data, chunk.end_ns)
            events += [(chunk.end_ns / SEC, e) for e in pipe.take_events()]
            for out in coord.host(t, pipe.take_tx()):
                line.put(out.t_ns, out.item)
        for other in ("sins", "nanoloc"):
            emu.lines[other].poll(t, t, emu.end_ns)
    assert [(e["event"], e["coordinator_api"], e["host_api"]) for _, e in events] == \
        [("api_mode_mismatch", 1, 2), ("api_mode_ok", 2, 2)]
    (t_bad, bad), (t_ok, _) = events
    assert 3 < t_bad < 3 + DB_PERIOD_S + 0.1 and 12 < t_ok < 12 + DB_PERIOD_S + 0.1
    assert bad["message"] == ("coordinator switched to API 1; the host decodes API 2: restart "
                              "the host with --api1 or send ATAP2")
    assert pipe.counts["api_mode_mismatch"] >= 1 and pipe.counts["imu"] > 1500
