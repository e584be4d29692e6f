"""The client's UART (emulator.uart_rx): hand-computed sampling vectors, parity, data bits,
stop bits, Linux's error delivery, a cross-check against a naive sampler of a 1-ns
waveform; and through real PTYs: a pyserial client at the wrong rate reads
garbage, at the right settings clean frames, and the recording stays the golden's."""
import os
import termios
import threading
import time
import tty

import numpy as np
import pytest
import serial

from navtwin.emulator.pty import PtyPort
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.uart_rx import ClientView, Framing, Received, Receiver, tty_bytes
from navtwin.protocols import xbee
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import Frame, XBeeDecoder, XBeeSinsChain, sins_decoder

LINE = Framing(115200)
CMSPAR = 0o10000000000  # Linux's stick-parity flag; Python's termios does not name it
LATER = 10_000_000  # ns: a chunk this much later finishes any frame of the one before
DEADLINE = 10.0


def read(tx, rx, *chunks):
    """Characters a receiver at *rx* reads from chunks (start_ns, bytes) sent at *tx*,
    plus an empty chunk long after, which says the line stayed idle."""
    r = Receiver(tx, rx)
    parts = [r.feed(t, data) for t, data in chunks]
    parts.append(r.feed(chunks[-1][0] + LATER, b""))
    values = np.concatenate([p.values for p in parts]).tobytes()
    flags = [np.concatenate([getattr(p, f) for p in parts]).tolist()
             for f in ("framing", "parity", "breaks")]
    return values, *flags


def apart(data, tx=LINE):
    """Each byte in its own chunk, the line idle between them."""
    return [(k * LATER, bytes([b])) for k, b in enumerate(data)]


def test_equal_settings_are_the_identity():
    data = bytes(range(256)) * 3
    assert read(LINE, LINE, (0, data))[0] == data


def test_0x0f_at_230400_by_hand():
    # Positions in 115200 bit times from the start edge: 0x0F is start 0 (low), d0-d3 at
    # 1-4 (high), d4-d7 at 5-8 (low), stop 9 (high). A 230400 bit is 0.5: samples at
    # 0.25 (start, low), 0.75 1.25 ... 4.25 -> d = 0,1,1,1,1,1,1,1 = 0xFE, stop 4.75 high.
    # Next falling edge after 4.75: 5 (d3 -> d4). Samples 5.25 (start, low), 5.75 ... 8.75
    # low, 9.25 high -> d = 0,0,0,0,0,0,0,1 = 0x80; stop at 9.75 high.
    assert read(LINE, Framing(230400), (0, b"\x0f")) == (b"\xfe\x80", [False] * 2, [False] * 2,
                                                          [False] * 2)


def test_0x0f_at_57600_by_hand():
    # A 57600 bit is 2 transmitter bits: the start sample at 1.0 falls on the edge and reads
    # the new bit, d0 (high): a glitch. Next falling edge after 1: 5. Samples 6 (start, low),
    # 8 (d7, low) then 10, 12, ... 22 on the idle line (high) -> d = 0,1,1,1,1,1,1,1 = 0xFE,
    # stop at 24 high.
    assert read(LINE, Framing(57600), (0, b"\x0f"))[:2] == (b"\xfe", [False])


def test_alternating_0x00_0xff_at_9600_by_hand():
    # 00 FF 00 FF ...: low at positions 0-8 and 10, high at 9 and 11-19, period 20. A 9600
    # bit is 12: samples at 6 + 12k, mod 20: 6 L (start), 18 H, 10 L, 2 L, 14 H, 6 L, 18 H,
    # 10 L, 2 L (d0-d7 = 1,0,0,1,0,1,0,0 = 0x29), 14 H (stop at 114, fine). The next falling
    # edge after 114 is 120: the end of the 12 bytes.
    assert read(LINE, Framing(9600), (0, b"\x00\xff" * 6)) == (b"\x29", [False], [False],
                                                                [False])


def weight(b):
    return bin(b).count("1")


@pytest.mark.parametrize("parity", ["E", "O"])
def test_8n1_read_with_parity_takes_the_stop_bit_for_parity(parity):
    # 8N1 read as 8x1: the data read right, the stop bit (1) read as the parity bit, the idle
    # line as the stop bit. Even parity wants an even count of ones: 1 + weight must be even,
    # so bytes of even weight are in error; under odd parity those of odd weight.
    values, framing, par, _ = read(LINE, Framing(115200, parity=parity), *apart(range(256)))
    assert values == bytes(range(256))
    assert not any(framing)
    assert par == [(weight(b) % 2 == 0) == (parity == "E") for b in range(256)]


def test_back_to_back_bytes_read_with_parity_lose_framing():
    # The stop sample lands in the next byte's start bit: a framing error, then the receiver
    # is out of step with the bytes.
    values, framing, _, _ = read(LINE, Framing(115200, parity="E"), (0, b"\x55" * 20))
    assert framing[0] and values != b"\x55" * len(values)


def test_7_data_bits_read_d7_as_the_stop_bit():
    values, framing, _, breaks = read(LINE, Framing(115200, bits=7), *apart(range(256)))
    assert values == bytes(b & 0x7F for b in range(256))
    assert breaks == [b == 0 for b in range(256)]  # every sample low: a break, not an error
    assert framing == [b & 0x80 == 0 and b != 0 for b in range(256)]


def test_stop_bits_never_garble():
    data = np.random.default_rng(3).integers(0, 256, 500, dtype=np.uint8).tobytes()
    two = Framing(115200, stop=2)
    assert read(LINE, two, (0, data))[0] == data
    assert read(two, LINE, (0, data))[0] == data
    assert not LINE.garbles(two) and LINE.garbles(Framing(9600))


@pytest.mark.parametrize("rx", [Framing(12500), Framing(1000), Framing(250000, parity="E")])
def test_frames_across_back_to_back_chunks_read_as_one_chunk(rx):
    # 125000 baud: a byte is 80 us, so chunk starts are whole ns and the split is exact
    tx = Framing(125000)
    data = np.random.default_rng(5).integers(0, 256, 300, dtype=np.uint8).tobytes()
    r = Receiver(tx, rx)
    cuts = [0, 1, 7, 30, 31, 100, 250, 300]
    split = b"".join(r.feed(a * 80_000, data[a:b]).values.tobytes()
                     for a, b in zip(cuts, cuts[1:]))
    whole = Receiver(tx, rx).feed(0, data).values.tobytes()
    assert split == whole and len(whole) > 1


@pytest.mark.parametrize("cflag, framing", [
    (termios.CS8 | termios.PARODD, Framing(9600)),  # left behind: no parity to a UART
    (termios.CS8 | CMSPAR, Framing(9600)),
    (termios.CS8 | CMSPAR | termios.PARODD, Framing(9600)),
    (termios.CS8 | termios.PARENB, Framing(9600, parity="E")),
    (termios.CS8 | termios.PARENB | termios.PARODD, Framing(9600, parity="O")),
    (termios.CS7 | termios.CSTOPB | termios.PARODD, Framing(9600, bits=7, stop=2)),
])
def test_termios_flags_are_read_as_a_uart_programs_its_line(cflag, framing):
    assert Framing.from_cflag(9600, cflag | termios.CREAD | termios.CLOCAL) == framing


@pytest.mark.pty
def test_a_raw_8n1_client_after_an_odd_parity_client_reads_no_parity():
    port = PtyPort("sins")
    try:
        with serial.Serial(port.pts, 115200, parity="O"):
            pass  # it leaves PARODD in the slave's termios (the PTY cleared its PARENB)
        fd = os.open(port.pts, os.O_RDWR | os.O_NOCTTY)
        try:
            tty.setraw(fd)  # cfmakeraw: clears PARENB, keeps PARODD
            assert termios.tcgetattr(fd)[2] & termios.PARODD
            assert port.check()
            assert port.client_framing()[0] == Framing(115200)
        finally:
            os.close(fd)
    finally:
        port.close()


def test_linux_delivery_of_errors_follows_the_8250_driver_and_n_tty():
    rec = Received(np.array([0x41, 0x42, 0x00], np.uint8), np.array([False, True, False]),
                   np.array([False, False, False]), np.array([False, False, True]))
    assert tty_bytes(rec, 0) == b"AB\x00"  # no INPCK: errors unchecked, a break reads 0x00
    assert tty_bytes(rec, termios.INPCK) == b"A\x00\x00"
    assert tty_bytes(rec, termios.INPCK | termios.IGNPAR) == b"A\x00"
    assert tty_bytes(rec, termios.IGNPAR) == b"AB\x00"  # IGNPAR acts only under INPCK
    assert tty_bytes(rec, termios.INPCK | termios.PARMRK) == b"A\xff\x00B\xff\x00\x00"
    assert tty_bytes(rec, termios.IGNBRK) == b"AB"
    assert tty_bytes(rec, termios.BRKINT) == b"AB"


# -- the cross-check: an independent naive receiver on a 1-ns waveform --------------------

TX_BIT_NS = 8000  # 125000 baud; receiver rates whose half bit is whole ns
RX_BAUDS = (125000, 100000, 62500, 250000, 40000, 50000, 31250, 160000, 200000, 500000)


def naive_line(chunks, tx, total_ns):
    wave = np.ones(total_ns, np.uint8)
    for start, data in chunks:
        bits = []
        for b in data:
            d = [(b >> i) & 1 for i in range(tx.bits)]
            bits += [0] + d
            if tx.parity != "N":
                bits.append((sum(d) + (tx.parity == "O")) % 2)
            bits += [1] * tx.stop
        for i, level in enumerate(bits):
            wave[start + i * TX_BIT_NS:start + (i + 1) * TX_BIT_NS] = level
    return wave


def naive_read(wave, rx):
    bit = 1_000_000_000 // rx.baud
    nsamples = 2 + rx.bits + (rx.parity != "N")
    out, t = [], 0  # hunt for a falling edge at or after t
    fall = np.flatnonzero((wave[1:] == 0) & (wave[:-1] == 1)) + 1
    fall = np.r_[[0] if wave[0] == 0 else [], fall].astype(int)
    while True:
        later = fall[fall >= t]
        if not len(later):
            return out
        e = int(later[0])
        samples = [e + bit // 2 + k * bit for k in range(nsamples)]
        if samples[-1] >= len(wave):
            return out
        lv = [int(wave[s]) for s in samples]
        if lv[0]:  # glitch
            t = samples[0] + 1
            continue
        d = lv[1:1 + rx.bits]
        value = sum(v << i for i, v in enumerate(d))
        brk = not any(lv)
        perr = rx.parity != "N" and (sum(d) + lv[1 + rx.bits]) % 2 == (rx.parity == "E")
        out.append((value, lv[-1] == 0 and not brk, perr and not brk, brk))
        t = samples[-1] + 1


@pytest.mark.parametrize("case", range(12))
def test_model_agrees_with_a_naive_sampler_of_the_waveform(case):
    rng = np.random.default_rng(100 + case)
    pick = lambda seq: seq[int(rng.integers(len(seq)))]  # noqa: E731
    tx = Framing(125000, pick([7, 8]), pick("NEO"), pick([1, 2]))
    rx = Framing(pick(RX_BAUDS), pick([5, 6, 7, 8]), pick("NEO"), pick([1, 2]))
    chunks, t = [], 0
    for _ in range(12):
        data = rng.integers(0, 1 << tx.bits, int(rng.integers(1, 20)), dtype=np.uint8).tobytes()
        chunks.append((t, data))
        t += len(data) * tx.frame_bits * TX_BIT_NS + pick([0, 0, 1, 3000, 50_000, 200_000])
    total = t + 20 * 1_000_000_000 // rx.baud
    expect = naive_read(naive_line(chunks, tx, total), rx)
    r = Receiver(tx, rx)
    parts = [r.feed(s, d) for s, d in chunks] + [r.feed(total, b"")]
    got = [(int(v), bool(f), bool(p), bool(b)) for part in parts
           for v, f, p, b in zip(part.values, part.framing, part.parity, part.breaks)]
    assert got == expect, (tx, rx)
    assert len(got) > 5


# -- the port's view of its client ----------------------------------------------------------

def test_view_events_once_per_change_and_on_a_device_rate_change():
    lines = []
    view = ClientView("xbee", LINE, notify=lines.append)
    view.settle(LINE, 0)
    view.settle(Framing(9600), 0)
    view.settle(Framing(9600), 0)
    assert lines == ["xbee: client at 9600 8N1, device 115200 8N1: the client reads garbage"]
    assert view.view(0, b"\x55" * 30, LINE) != b"\x55" * 30
    assert view.garbled_bytes == 30
    view.view(LATER, b"\x55" * 30, Framing(9600))  # BD: the device now runs at the client's rate
    assert lines[-1] == "xbee: client at the device's settings (9600 8N1) again"
    assert view.view(2 * LATER, b"\x55", Framing(9600)) == b"\x55"
    view.settle(None, 0)
    assert len(lines) == 2


# -- through PTYs -------------------------------------------------------------------------

def bd(value: int, fid: int) -> bytes:
    """The host's ATBD API frame (escaped, as AP 2 wants it)."""
    return xbee.build(0x08, True, frame_id=fid, command=b"BD", parameter=bytes((value,)))


def test_the_device_reads_a_client_at_another_rate_as_garbage_and_at_its_own_clean():
    view = ClientView("xbee", Framing(115200))
    view.settle(Framing(115200), 0)
    frame = bd(7, 2)
    assert view.heard(0, frame, Framing(115200)) == frame
    heard = view.heard(LATER, frame, Framing(9600)) + view.heard(2 * LATER, b"", Framing(9600))
    assert heard != frame and not [e for e in XBeeDecoder(True).feed(heard)
                                   if isinstance(e, Frame)]
    assert view.garbled_host_bytes == len(frame)
    view.settle(Framing(9600), 0)  # the host follows the device's BD
    assert view.heard(3 * LATER, frame, Framing(9600)) == frame


class Run:
    """An Emulation in a thread; its event lines can be waited for."""

    def __init__(self, **kw) -> None:
        self.stop = threading.Event()
        self.lines: list[str] = []
        self.seen = 0  # lines up to the last one waited for
        self.cond = threading.Condition()
        self.emu = Emulation(load_scenario("office"), progress=self._line, **kw)
        self.summary = None
        self.thread = threading.Thread(target=self._run)
        self.thread.start()

    def _run(self) -> None:
        self.summary = self.emu.run(self.stop)

    def _line(self, line: str) -> None:
        with self.cond:
            self.lines.append(line)
            self.cond.notify_all()

    def wait_for(self, text: str) -> None:
        """Until an event line after the last one waited for contains *text*. A line that came
        before this call counts: the action that causes it (a client's open, its termios) may
        be noticed by the emulator's thread before the test's thread gets here."""
        def found() -> bool:
            for i in range(self.seen, len(self.lines)):
                if text in self.lines[i]:
                    self.seen = i + 1
                    return True
            return False

        with self.cond:
            assert self.cond.wait_for(found, DEADLINE), (text, self.lines[self.seen:])


@pytest.fixture
def live(tmp_path):
    run = Run(seed=1, speed=1.0, duration_s=60, link_dir=tmp_path / "links")
    yield run
    run.stop.set()
    run.thread.join(DEADLINE)
    run.emu.close()


def frames_in(ser, n=900):
    """SINS frames a decoder finds in the next *n* bytes the client reads."""
    ser.reset_input_buffer()  # what was written before the emulator saw the settings
    data = b""
    end = time.monotonic() + DEADLINE
    while len(data) < n and time.monotonic() < end:
        data += ser.read(n - len(data))
    assert len(data) == n
    return [ev for ev in sins_decoder().feed(data) if isinstance(ev, Frame)]


@pytest.mark.pty
@pytest.mark.parametrize("wrong", [dict(baudrate=9600), dict(baudrate=57600)])
def test_a_client_at_wrong_settings_reads_garbage_and_clean_frames_again(live, wrong):
    link = live.emu.links["sins"]
    with serial.Serial(link, timeout=1.0, **wrong) as ser:
        live.wait_for("sins: client at")
        assert frames_in(ser, 300 if wrong["baudrate"] == 9600 else 900) == []
    live.wait_for("sins: client gone")  # the next client starts clean
    view = live.emu.views["sins"]
    assert view.framing_errors + view.parity_errors > 0
    with serial.Serial(link, 115200, timeout=1.0) as ser:
        frames = frames_in(ser)
        assert len(frames) >= 25
        seqs = [f.fields["seq"] for f in frames]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))


@pytest.mark.pty
def test_the_recording_keeps_the_devices_bytes_whatever_the_clients_settings(root, tmp_path):
    gold = Recording(root / "fixtures" / "golden" / "office")
    run = Run(seed=gold.meta["seed"], speed=1.0, duration_s=2.0, link_dir=tmp_path / "links",
              record=tmp_path / "rec")
    sers = [serial.Serial(run.emu.links[p], **kw) for p, kw in
            (("sins", dict(baudrate=9600)), ("xbee", dict(baudrate=57600)),
             ("nanoloc", dict(baudrate=230400)))]
    try:
        run.thread.join(60)
    finally:
        for ser in sers:
            ser.close()
        run.emu.close()
    assert all(run.summary["ports"][p]["garbled_bytes"] > 0 for p in ("sins", "xbee", "nanoloc"))
    again = Recording(tmp_path / "rec")
    for port in ("sins", "xbee", "nanoloc"):
        rt = [(c.data, c.t_device_ns) for c in again.chunks(port)]
        assert rt == [(c.data, c.t_device_ns) for c in gold.chunks(port)
                      if c.t_device_ns < 2_000_000_000], port


@pytest.mark.pty
def test_a_coordinator_at_9600_does_not_understand_a_host_still_at_115200(tmp_path):
    """ATBD3, then ATBD7 sent at 115200 (garbage to a 9600 UART: no answer, the rate stays),
    then ATBD7 sent at 9600 (answered: the coordinator is back at 115200)."""
    run = Run(seed=1, speed=1.0, duration_s=60, link_dir=tmp_path / "links",
              record=tmp_path / "rec")
    view = run.emu.views["xbee"]
    try:
        with serial.Serial(run.emu.links["xbee"], 115200, timeout=0.2) as ser:
            ser.write(bd(3, 1))
            run.wait_for("xbee: client at 115200 8N1, device 9600 8N1")
            ser.write(bd(7, 2))
            end = time.monotonic() + DEADLINE
            while view.garbled_host_bytes < len(bd(7, 2)):
                assert time.monotonic() < end, "the host's frame never reached the coordinator"
                time.sleep(0.01)
            ser.baudrate = 9600
            run.wait_for("xbee: client at the device's settings (9600 8N1) again")
            ser.write(bd(7, 3))
            run.wait_for("xbee: client at 9600 8N1, device 115200 8N1")
    finally:
        run.stop.set()
        run.thread.join(DEADLINE)
        run.emu.close()
    chain = XBeeSinsChain(escaped=True)
    answered = [ev.fields["frame_id"] for c in Recording(tmp_path / "rec").chunks("xbee")
                for ev in chain.feed(c.data) if ev.format == "xbee" and ev.type == 0x88]
    assert answered == [1, 3]
