"""The coordinator's API-mode behaviour, frame by frame, against Digi's worked examples
(xbee-api-facts.md) and digi-xbee's own packet parser as an independent implementation."""
from collections import namedtuple

import numpy as np
import pytest
from digi.xbee.models.mode import OperatingMode
from digi.xbee.packets.base import XBeeAPIPacket
from digi.xbee.packets.factory import build_frame

from navtwin.emulator.coordinator import (ADDRESS_TIMEOUT_NS, MS, RESET_NS, SERIAL_TX_BUFFER, START_NS,
                                  Coordinator, Remote, identity_registers)
from navtwin.protocols import xbee

RfPacket = namedtuple("RfPacket", "src64 src16 options data")
COORD = {"SH": 0x0013A200, "SL": 0x40A1B2C3, "NI": "LAB-COORD", "HV": 0x1E46, "VR": 0x21A7}
ROUTER = {"SH": 0x0013A200, "SL": 0x40A1B2D4, "NI": "SINS-ROUTER", "HV": 0x1E46, "VR": 0x22A7,
          "MY": 0x7D84, "AP": 0, "RO": 3}
ROUTER64 = 0x0013A20040A1B2D4


class FakeLink:
    """unicast answers from a script, recording the calls."""

    def __init__(self, *answers):
        self.answers = list(answers) or [(True, 0, 7 * MS)]
        self.calls = []

    def unicast(self, t_ns, nbytes, air=None):
        self.calls.append((t_ns, nbytes))
        return self.answers[min(len(self.calls) - 1, len(self.answers) - 1)]


def make(link=None, api_mode=2, **coord):
    regs = identity_registers({**COORD, **coord}, MY=0, CE=1, AP=api_mode, BD=7)
    return Coordinator(regs, [Remote(identity_registers(ROUTER))], link or FakeLink(),
                       np.random.default_rng(1))


def emit(c, outputs):
    """Render outputs in time order as the UART would: [(t_ns, bytes)]."""
    return [(o.t_ns, c.render(o.t_ns, o.item)) for o in sorted(outputs, key=lambda o: o.t_ns)]


def digi(frame: bytes, escaped=True):
    """The frame as digi-xbee's reader sees it: its own unescaping, then its parser."""
    if escaped:
        frame = frame[:1] + XBeeAPIPacket.unescape_data(frame[1:])
    return build_frame(bytearray(frame),
                       OperatingMode.ESCAPED_API_MODE if escaped else OperatingMode.API_MODE)


def at(cmd: bytes, param=b"", fid=1, queued=False, escaped=True):
    return xbee.build(0x09 if queued else 0x08, escaped, frame_id=fid, command=cmd, parameter=param)


def test_power_up_modem_status_matches_digi_examples():
    c = make()
    assert emit(c, c.power_up()) == [(0, bytes.fromhex("7E00028A0075")),
                                     (5 * MS, bytes.fromhex("7E00028A066F"))]


def test_bd_set_example_answers_the_documented_frame_and_changes_the_rate_after_it():
    c = make()
    out = c.host(10 * MS, bytes.fromhex("7E00060801424404B0BC"))  # Digi: set BD=0x04B0
    assert [o.t_ns for o in out] == [13 * MS]  # answered after the response delay
    assert c.baud == 115200  # not before the answer has gone out
    assert emit(c, out) == [(13 * MS, bytes.fromhex("7E00058801424400F0"))]
    assert c.baud == 0x04B0


@pytest.mark.parametrize("cmd,value", [(b"VR", 0x21A7), (b"HV", 0x1E46), (b"SH", 0x0013A200),
                                       (b"SL", 0x40A1B2C3), (b"MY", 0), (b"AP", 2), (b"BD", 7),
                                       (b"CE", 1), (b"AI", 0), (b"NP", 84), (b"NT", 0x3C),
                                       (b"AO", 0), (b"NO", 0)])
def test_queries_answer_the_register_value(cmd, value):
    c = make()
    (t, frame), = emit(c, c.host(0, at(cmd, fid=0x52, queued=True)))
    p = digi(frame)
    assert (p.frame_id, p.command, p.status.code) == (0x52, cmd.decode(), 0)
    assert int.from_bytes(p.command_value, "big") == value


def test_node_identifier_is_text_and_settable():
    c = make()
    (_, frame), = emit(c, c.host(0, at(b"NI")))
    assert digi(frame).command_value == b"LAB-COORD"
    (_, frame), = emit(c, c.host(0, at(b"NI", b"BENCH 2")))
    assert digi(frame).status.code == 0
    (_, frame), = emit(c, c.host(0, at(b"NI")))
    assert digi(frame).command_value == b"BENCH 2"


@pytest.mark.parametrize("cmd,param,status", [
    (b"XX", b"", 2),            # unknown command
    (b"N?", b"", 2),            # not on 2x7x firmware
    (b"SH", b"\x01", 1),        # read-only
    (b"AP", b"\x00", 3),        # transparent mode is not emulated
    (b"AP", b"\x03", 3),
    (b"NT", b"\x10", 3),        # below 0x20
    (b"NI", b"x" * 21, 3),      # too long
    (b"BD", b"\x00\x00\x00\x00\x08", 3),  # wider than the register
])
def test_errors_use_the_documented_status(cmd, param, status):
    c = make()
    (_, frame), = emit(c, c.host(0, at(cmd, param)))
    assert digi(frame).status.code == status


def test_frame_id_zero_acts_without_answer():
    c = make()
    assert c.host(0, at(b"NI", b"SILENT", fid=0)) == []
    assert c.registers.values["NI"] == b"SILENT"


def test_queued_set_waits_for_ac_or_the_next_set():
    c = make()
    emit(c, c.host(0, bytes.fromhex("7E0005090142440768")))  # Digi: queue BD=7 ...
    emit(c, c.host(0, at(b"NT", b"\x40", queued=True)))
    (_, frame), = emit(c, c.host(0, at(b"NT")))
    assert digi(frame).command_value == b"\x3c"  # queued, not applied
    emit(c, c.host(0, at(b"AC")))
    (_, frame), = emit(c, c.host(0, at(b"NT")))
    assert digi(frame).command_value == b"\x40"
    emit(c, c.host(0, at(b"NO", b"\x01", queued=True)))
    emit(c, c.host(0, at(b"NT", b"\x50")))  # an 0x08 set applies the queue too
    assert c.registers.values["NO"] == 1 and c.registers.values["NT"] == 0x50


def test_ap_change_switches_escaping_after_the_answer():
    c = make(api_mode=2)
    out = c.host(0, at(b"AP", b"\x01"))
    (_, ok), = emit(c, out)
    assert digi(ok, escaped=True).status.code == 0
    assert not c.escaped
    pkt = RfPacket(ROUTER64, 0x7D84, 0x01, b"\x13\x11")
    frame = c.render(0, pkt)
    assert frame == xbee.build(0x90, False, src64=ROUTER64, src16=0x7D84, options=1,
                               data=b"\x13\x11")
    # and the host must now talk API 1: a frame with a 0x13 inside is read plainly
    (_, ok), = emit(c, c.host(0, at(b"DL", b"\x00\x00\x00\x13", escaped=False)))
    assert digi(ok, escaped=False).status.code == 0 and c.registers.values["DL"] == 0x13


def test_receive_packet_matches_digi_example():
    c = make(api_mode=1)
    pkt = RfPacket(0x0013A20040522BAA, 0x7D84, 0x01, b"RxData")
    frame = c.render(0, c.received(0, pkt).item)
    assert frame == bytes.fromhex("7E0012900013A20040522BAA7D8401527844617461") + b"\x0d"


def test_receive_packet_escaped_round_trips_through_digi():
    c = make(api_mode=2)
    data = bytes(range(0x0F, 0x15)) + b"\x7e\x7d"
    frame = c.render(0, RfPacket(ROUTER64, 0x7D84, 0x01, data))
    p = digi(frame)
    assert p.rf_data == data and p.x64bit_source_addr.address == ROUTER64.to_bytes(8, "big")


def test_explicit_rx_when_ao_is_1():
    c = make()
    emit(c, c.host(0, at(b"AO", b"\x01")))
    p = digi(c.render(0, RfPacket(ROUTER64, 0x7D84, 0x01, b"abc")))
    assert type(p).__name__ == "ExplicitRXIndicatorPacket"
    assert (p.source_endpoint, p.dest_endpoint, p.cluster_id, p.profile_id, p.rf_data) == \
        (0xE8, 0xE8, 0x0011, 0xC105, b"abc")


def test_rf_packets_that_do_not_fit_the_serial_transmit_buffer_are_dropped_whole():
    c = make()
    pkt = RfPacket(ROUTER64, 0x7D84, 0x01, b"\x7e" * 30)  # escapes count: sized as sent
    size = len(c.render(0, pkt))
    assert size >= 16 + 2 * 30  # 0x90 overhead + 30 escaped bytes
    assert c.admit(0, pkt, SERIAL_TX_BUFFER - size) == size
    assert c.admit(0, pkt, SERIAL_TX_BUFFER - size + 1) is None
    assert c.dropped_tx_buffer == 1
    # answers to the host are not RF packets: kept whatever is queued
    (answer,) = c.host(0, at(b"VR"))
    assert c.admit(answer.t_ns, answer.item, 10 * SERIAL_TX_BUFFER) == len(
        c.render(answer.t_ns, answer.item))
    assert c.dropped_tx_buffer == 1


def tx(dest64=ROUTER64, dest16=0xFFFE, data=b"hello", fid=7, options=0):
    return xbee.build(0x10, True, frame_id=fid, dest64=dest64, dest16=dest16, radius=0,
                      options=options, data=data)


def test_transmit_to_router_reports_success_after_link_latency():
    link = FakeLink((True, 2, 40 * MS))
    c = make(link)
    (t, frame), = emit(c, c.host(100 * MS, tx()))
    p = digi(frame)
    assert t == 140 * MS and link.calls == [(100 * MS, 5)]
    assert (p.frame_id, p.x16bit_dest_addr.address, p.transmit_retry_count, p.transmit_status.code,
            p.discovery_status.code) == (7, b"\x7d\x84", 2, 0x00, 0x01)


def test_transmit_to_router_by_16_bit_address():
    c = make()
    (_, frame), = emit(c, c.host(0, tx(dest64=0xFFFFFFFFFFFFFFFF, dest16=0x7D84)))
    assert digi(frame).transmit_status.code == 0x00


def test_transmit_failure_is_network_ack_failure():
    c = make(FakeLink((False, 3, 900 * MS)))
    (t, frame), = emit(c, c.host(0, tx()))
    p = digi(frame)
    assert t == 900 * MS and p.transmit_status.code == 0x21 and p.transmit_retry_count == 3


@pytest.mark.parametrize("kw,status,delay", [
    ({"data": bytes(85)}, 0x74, 3 * MS),                          # over NP = 84
    ({"dest64": 0x0013A20040FFFFFF}, 0x24, 3 * MS + ADDRESS_TIMEOUT_NS),
    ({"dest64": 0xFFFFFFFFFFFFFFFF, "dest16": 0x1234}, 0x25, 3 * MS + ADDRESS_TIMEOUT_NS),
    ({"dest64": 0x0013A20040A1B2C3}, 0x23, 3 * MS),               # itself
    ({"dest64": 0xFFFF, "data": bytes(92)}, 0x00, 3 * MS),        # broadcast, 92 fits
    ({"dest64": 0xFFFF, "data": bytes(93)}, 0x74, 3 * MS),
])
def test_transmit_status_codes(kw, status, delay):
    link = FakeLink()
    c = make(link)
    (t, frame), = emit(c, c.host(0, tx(**kw)))
    assert digi(frame).transmit_status.code == status and t == delay
    assert link.calls == []  # none of these reaches the link model


def test_transmit_with_frame_id_zero_is_silent_but_still_sent():
    link = FakeLink()
    c = make(link)
    assert c.host(0, tx(fid=0)) == [] and len(link.calls) == 1


def remote_at(cmd, param=b"", fid=0x55, dest64=ROUTER64, options=0x02):
    return xbee.build(0x17, True, frame_id=fid, dest64=dest64, dest16=0xFFFE, options=options,
                      command=cmd, parameter=param)


def test_remote_at_reads_the_router_register():
    link = FakeLink((True, 0, 6 * MS), (True, 0, 5 * MS))
    c = make(link)
    (t, frame), = emit(c, c.host(0, remote_at(b"SL")))
    p = digi(frame)
    assert t == 11 * MS and link.calls == [(0, 4), (6 * MS, 8)]
    assert (p.frame_id, p.command, p.status.code, p.command_value) == \
        (0x55, "SL", 0, bytes.fromhex("40A1B2D4"))
    assert p.x16bit_source_addr.address == b"\x7d\x84"


def test_remote_at_response_matches_digi_example():
    regs = identity_registers({**COORD}, MY=0, CE=1, AP=1, BD=7)
    router = Remote(identity_registers({**ROUTER, "SL": 0x40522BAA}))
    c = Coordinator(regs, [router], FakeLink(), np.random.default_rng(1))
    request = xbee.build(0x17, False, frame_id=0x55, dest64=0x0013A20040522BAA, dest16=0xFFFE,
                         options=0, command=b"SL", parameter=b"")
    (_, frame), = emit(c, c.host(0, request))
    assert frame == bytes.fromhex("7E001397550013A20040522BAA7D84534C0040522BAAF0")


def test_remote_at_set_applies_with_option_2_and_router_has_no_ce():
    c = make()
    emit(c, c.host(0, remote_at(b"NI", b"CART")))
    (_, frame), = emit(c, c.host(0, remote_at(b"NI")))
    assert digi(frame).command_value == b"CART"
    emit(c, c.host(0, remote_at(b"NI", b"QUEUED", options=0)))
    (_, frame), = emit(c, c.host(0, remote_at(b"NI")))
    assert digi(frame).command_value == b"CART"
    (_, frame), = emit(c, c.host(0, remote_at(b"CE")))
    assert digi(frame).status.code == 2


@pytest.mark.parametrize("answers", [[(False, 3, 50 * MS)],
                                     [(True, 0, 5 * MS), (False, 3, 50 * MS)]])
def test_remote_at_lost_on_the_link_is_status_4(answers):
    c = make(FakeLink(*answers))
    (_, frame), = emit(c, c.host(0, remote_at(b"SL")))
    p = digi(frame)
    assert p.status.code == 4 and not p.command_value


def test_remote_at_to_unknown_address_is_status_4():
    c = make()
    (t, frame), = emit(c, c.host(0, remote_at(b"SL", dest64=0x0013A20040000001)))
    assert digi(frame).status.code == 4 and t == 3 * MS + ADDRESS_TIMEOUT_NS


# The S2B's factory defaults, restated from Digi's "XBee/XBee-PRO ZB RF Modules" manual
# (90000976 rev. J, XBee Command Reference Tables): what XCTU reads from a module it has
# discovered (its whole parameter list), and digi-xbee's get_io_configuration and friends.
S2B_DEFAULTS = {
    "D0": 1, "D1": 0, "D2": 0, "D3": 0, "D4": 0, "D5": 1, "D6": 0, "D7": 1,  # button, LED, CTS
    "P0": 1, "P1": 0, "P2": 0,  # RSSI PWM
    "IR": 0, "IC": 0, "LT": 0, "RP": 0x28, "V+": 0,
    "NB": 0, "SB": 0, "AO": 0, "DD": 0x30000, "NT": 0x3C, "NO": 0, "NH": 0x1E, "NJ": 0xFF,
    "SC": 0x1FFE, "SD": 3, "ZS": 0, "JV": 0, "NW": 0, "JN": 0, "AR": 0xFF,
    "PL": 4, "PM": 1, "EE": 0, "SM": 0, "SN": 1, "SP": 0x20, "ST": 0x1388,
}


@pytest.mark.parametrize("cmd,value", S2B_DEFAULTS.items())
def test_router_and_coordinator_answer_the_s2b_parameters_with_factory_defaults(cmd, value):
    c = make()
    (_, remote), = emit(c, c.host(0, remote_at(cmd.encode())))
    (_, local), = emit(c, c.host(0, at(cmd.encode())))
    for p in (digi(remote), digi(local)):
        assert (p.status.code, int.from_bytes(p.command_value, "big")) == (0, value)


@pytest.mark.parametrize("cmd,value,status", [(b"D0", b"\x02", 0), (b"D4", b"\x02", 3),
                                              (b"D7", b"\x07", 0), (b"P1", b"\x01", 3),
                                              (b"IR", b"\x00\x31", 3), (b"IR", b"\x03\xE8", 0)])
def test_router_io_settings_are_checked_like_the_manual_says(cmd, value, status):
    c = make()
    (_, frame), = emit(c, c.host(0, remote_at(cmd, value)))
    assert digi(frame).status.code == status
    (_, frame), = emit(c, c.host(0, remote_at(cmd)))
    assert (digi(frame).command_value == value) == (status == 0)


def node_desc_req(fid=1, nwk=0x7D84, dest16=0x7D84):
    return xbee.build(0x11, True, frame_id=fid, dest64=ROUTER64, dest16=dest16, src_endpoint=0,
                      dest_endpoint=0, cluster=0x0002, profile=0, radius=0, options=0,
                      data=bytes((fid,)) + nwk.to_bytes(2, "little"))


def test_router_answers_the_zdo_node_descriptor_request_as_a_router():
    link = FakeLink((True, 0, 6 * MS), (True, 0, 5 * MS))
    c = make(link)
    emit(c, c.host(0, at(b"AO", b"\x01")))  # digi-xbee sets AO = 1 for ZDO
    (t1, status), (t2, answer) = emit(c, c.host(0, node_desc_req(fid=9)))
    assert (t1, t2) == (6 * MS, 11 * MS) and link.calls == [(0, 3), (6 * MS, 17)]
    assert digi(status).transmit_status.code == 0x00
    p = digi(answer)
    assert type(p).__name__ == "ExplicitRXIndicatorPacket"
    assert (p.x64bit_source_addr.address, p.x16bit_source_addr.address) == \
        (ROUTER64.to_bytes(8, "big"), b"\x7d\x84")
    assert (p.source_endpoint, p.dest_endpoint, p.cluster_id, p.profile_id) == (0, 0, 0x8002, 0)
    data = bytes(p.rf_data)
    assert data[:4] == bytes((9, 0x00, 0x84, 0x7D))  # transaction, SUCCESS, NWK address (LE)
    assert len(data) == 4 + 13 and data[4] & 0x07 == 1  # logical type: router
    assert data[7:9] == bytes((0x1E, 0x10))  # Digi's manufacturer code


def test_zdo_answer_needs_ao_bit_0_and_the_nodes_own_address():
    c = make()
    (_, status), = emit(c, c.host(0, node_desc_req()))  # AO = 0: the 0x8B only
    assert digi(status).transmit_status.code == 0x00
    emit(c, c.host(0, at(b"AO", b"\x01")))
    _, (_, answer) = emit(c, c.host(0, node_desc_req(nwk=0x1234)))
    assert bytes(digi(answer).rf_data) == bytes((1, 0x81, 0x34, 0x12))  # DEVICE_NOT_FOUND


def test_node_discovery_reports_the_router_within_nt():
    c = make()
    (t, frame), = emit(c, c.host(0, at(b"ND", fid=9)))  # the router's answer, nothing else
    assert 3 * MS < t < 0x3C * 100 * MS
    value = digi(frame).command_value
    ni_end = value.index(b"\x00", 10)
    assert value[:2] == b"\x7d\x84" and value[2:10] == ROUTER64.to_bytes(8, "big")
    assert value[10:ni_end] == b"SINS-ROUTER"
    assert value[ni_end + 1:] == bytes.fromhex("FFFE" "01" "00" "C105" "101E")  # no DD: NO = 0


def test_node_discovery_with_no_bit0_adds_device_type_identifier():
    c = make()
    emit(c, c.host(0, at(b"NO", b"\x01")))
    *_, (_, frame) = emit(c, c.host(0, at(b"ND")))
    assert digi(frame).command_value.endswith(bytes.fromhex("C105101E00030000"))


def test_node_discovery_by_name():
    c = make()
    assert len(c.host(0, at(b"ND", b"NOBODY"))) == 0
    assert len(c.host(0, at(b"ND", b"SINS-ROUTER"))) == 1


def test_software_reset_loses_unsaved_values_and_reports_modem_status():
    c = make()
    emit(c, c.host(0, at(b"NT", b"\x40")))
    emit(c, c.host(0, at(b"WR")))
    emit(c, c.host(0, at(b"NI", b"UNSAVED")))
    out = emit(c, c.host(10 * MS, at(b"FR")))
    assert [t for t, _ in out] == [13 * MS, 13 * MS + RESET_NS, 13 * MS + RESET_NS + START_NS]
    assert [digi(f).get_frame_type_value() for _, f in out] == [0x88, 0x8A, 0x8A]
    assert [digi(f).modem_status.code for _, f in out[1:]] == [0x01, 0x06]
    assert c.registers.values["NT"] == 0x40 and c.registers.values["NI"] == b"LAB-COORD"
    # while it reboots the radio reports nothing
    assert c.render(13 * MS + RESET_NS, RfPacket(ROUTER64, 0x7D84, 1, b"x")) == b""
    assert c.render(13 * MS + RESET_NS + START_NS, RfPacket(ROUTER64, 0x7D84, 1, b"x")) != b""


def test_garbage_and_bad_checksums_are_ignored():
    c = make()
    bad = bytearray(at(b"VR"))
    bad[-1] ^= 0xFF
    assert c.host(0, b"\x00\xff" + bytes(bad) + b"junk") == []
    assert len(c.host(0, at(b"VR"))) == 1
