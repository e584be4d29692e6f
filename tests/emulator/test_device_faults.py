"""Device-level fault kinds, checked on the bytes they put on the wire against the same run
without them (same seed: what the fault does not touch is byte-identical)."""
import numpy as np
import pytest

from navtwin.emulator.runner import Emulation
from navtwin.protocols import nanoloc, xbee
from navtwin.protocols.stream import Frame, XBeeDecoder, XBeeSinsChain, nanoloc_decoder, sins_decoder

from .world_helpers import variant

SEC = 1_000_000_000


def chunks(sc, seed=1, duration_s=9.0):
    """Every chunk the ports deliver, with its device time (the in-memory sink)."""
    out = []
    with Emulation(sc, seed, speed=None, duration_s=duration_s, ports=False,
                   sink=out.append) as emu:
        emu.run()
    return out


def frames(cs, port, decoder):
    """(start_ns, frame) of each frame of *port*, timed by the chunk that ends it."""
    out = []
    for c in cs:
        if c.port == port:
            out += [(c.start_ns, f) for f in decoder.feed(c.data) if isinstance(f, Frame)]
    return out


def with_fault(tmp_path, toml):
    return variant(tmp_path, "office", f"[[faults]]\n{toml}")


def test_board_reset_silences_the_board_and_its_counter_starts_again(tmp_path):
    clean = frames(chunks(variant(tmp_path, "office", "")), "sins", sins_decoder())
    got = frames(chunks(with_fault(tmp_path, 'kind = "board_reset"\nstart_s = 4.0\nend_s = 4.5\n')),
                 "sins", sins_decoder())
    before = [f for t, f in got if t < 4 * SEC]
    assert [f.raw for f in before] == [f.raw for t, f in clean if t < 4 * SEC]
    assert not [t for t, _ in got if 4 * SEC <= t < 4.5 * SEC]
    after = [f for t, f in got if t >= 4.5 * SEC]
    assert after[0].fields["seq"] == 0  # counts from power-up again
    assert all(b.fields["seq"] == a.fields["seq"] + 1 for a, b in zip(after, after[1:]))
    # the crystal's schedule goes on: the frames after are at the clean run's instants
    assert [t for t, _ in got if t >= 4.5 * SEC] == [t for t, _ in clean if t >= 4.5 * SEC]
    # and through the radio: the router forwards what the board writes
    radio = [f for _, f in frames(chunks(with_fault(
        tmp_path, 'kind = "board_reset"\nstart_s = 4.0\nend_s = 4.5\n')), "xbee", XBeeSinsChain(True))
        if f.format == "sins"]
    seqs = [f.fields["seq"] for f in radio]
    assert seqs.count(0) == 2  # power-up, and the reset


def test_coordinator_reset_reports_nothing_then_powers_up_again(tmp_path):
    cs = chunks(with_fault(tmp_path, 'kind = "coordinator_reset"\nstart_s = 4.0\nend_s = 5.0\n'))
    fs = frames(cs, "xbee", XBeeDecoder(True))
    rx = [t for t, f in fs if f.type == xbee.FrameType.RECEIVE_PACKET]
    # nothing starts on the line while the radio is off (a packet in flight at 4 s finishes)
    assert not [t for t in rx if 4.0 * SEC + 5_000_000 <= t < 5 * SEC]
    assert [t for t in rx if t >= 5 * SEC] and [t for t in rx if t < 4 * SEC]
    modem = [(t, f.fields["status"]) for t, f in fs if f.type == xbee.FrameType.MODEM_STATUS]
    assert [m for _, m in modem] == [xbee.ModemStatus.HARDWARE_RESET, xbee.ModemStatus.COORDINATOR_STARTED] * 2
    assert modem[2][0] == 5 * SEC  # the power-up at the end of the episode


def test_link_fade_loses_attempts_and_a_total_fade_loses_every_packet(tmp_path):
    def radio_seqs(toml):
        fs = frames(chunks(with_fault(tmp_path, toml)), "xbee", XBeeSinsChain(True))
        return {f.fields["seq"] for _, f in fs if f.format == "sins"}

    clean = radio_seqs('kind = "link_loss"\nstart_s = 8.9\nend_s = 8.95\n')  # a tiny episode
    total = radio_seqs('kind = "link_fade"\nstart_s = 4.0\nend_s = 5.0\nattempt_loss = 1.0\n')
    lost = clean - total
    # about one second of SINS samples (100) never reach the host, the rest do
    assert 90 <= len(lost) <= 110 and all(390 <= s <= 510 for s in lost), sorted(lost)[:5]
    half = radio_seqs('kind = "link_fade"\nstart_s = 4.0\nend_s = 5.0\nattempt_loss = 0.5\n')
    assert len(clean - half) < len(lost) // 4  # retries get most packets through


def test_range_value_errors_flag_one_anchor_and_change_nothing_else(tmp_path):
    clean = frames(chunks(variant(tmp_path, "office", "")), "nanoloc", nanoloc_decoder())
    got = frames(chunks(with_fault(tmp_path, 'kind = "range_value_error"\nanchor = 2\n'
                                              'start_s = 3.0\nend_s = 6.0\nprobability = 1.0\n')),
                 "nanoloc", nanoloc_decoder())
    assert len(got) == len(clean)
    flagged = 0
    for (_, g), (_, w) in zip(got, clean):
        g, w = g.fields, w.fields
        if g["anchor"] == 2 and 3.05 <= g["t_us"] / 1e6 < 5.95 and w["status"] == nanoloc.STATUS_COMPLETE:
            assert g["status"] == nanoloc.STATUS_VALUE_ERROR and tuple(g["tau"]) == (0, 0, 0, 0)
            flagged += 1
        elif g["anchor"] != 2:
            assert g == w
    assert flagged > 20


@pytest.mark.parametrize("p", [0.3])
def test_range_value_error_rate_matches_its_probability(tmp_path, p):
    got = frames(chunks(with_fault(tmp_path, f'kind = "range_value_error"\nanchor = 1\n'
                                              f'start_s = 0.0\nend_s = 9.0\nprobability = {p}\n')),
                 "nanoloc", nanoloc_decoder())
    ones = [f.fields["status"] for _, f in got if f.fields["anchor"] == 1]
    n, k = len(ones), sum(s == nanoloc.STATUS_VALUE_ERROR for s in ones)
    assert abs(k - p * n) < 4 * np.sqrt(n * p * (1 - p)), (k, n)  # 4 sigma of a binomial


def test_router_rejoin_loses_its_packets_then_it_sends_under_a_new_address(tmp_path):
    cs = chunks(with_fault(tmp_path, 'kind = "router_rejoin"\nstart_s = 4.0\nend_s = 5.0\n'))
    rx = [(t, f) for t, f in frames(cs, "xbee", XBeeDecoder(True))
          if f.type == xbee.FrameType.RECEIVE_PACKET]
    before = {f.fields["src16"] for t, f in rx if t < 4 * SEC}
    after = {f.fields["src16"] for t, f in rx if t > 5.1 * SEC}
    assert len(before) == len(after) == 1 and before != after  # a new 16-bit address
    assert {f.fields["src64"] for _, f in rx} == {rx[0][1].fields["src64"]}  # the same radio
    assert not [t for t, _ in rx if 4.01 * SEC <= t < 5 * SEC]  # out of the network
