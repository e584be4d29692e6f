"""The fault seam: wrappers between a device and its UART line, and the registry of fault
kinds (device-level ones act on a model, line-level ones install a wrapper)."""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass

import pytest

from navtwin.common.schema import between, key
from navtwin.emulator.faults import Fault, FaultError, LineFault, register, unregister
from navtwin.emulator.runner import Emulation, RunError
from navtwin.emulator.scenario import ScenarioError
from navtwin.emulator.uart import Line, LineWrapper, Wire
from navtwin.protocols.ports import names
from navtwin.protocols.recording import Recording
from navtwin.protocols.serial import wire_ns

from .world_helpers import variant
from ..packages import write

PORTS = names()  # the lab's ports, in its order

SEC = 1_000_000_000
SHIPPED = ["anchor_outage", "nlos", "link_loss", "link_fade", "range_value_error", "board_reset",
           "coordinator_reset", "router_rejoin", "bit_errors", "byte_drop", "byte_duplicate",
           "byte_insert", "garbage", "burst_loss", "latency", "bandwidth", "slicing", "stuck"]


def sent(line: Line, until_ns: int = 10 * SEC) -> list:
    return [(c.start_ns, c.end_ns, c.data) for c in line.poll(until_ns, until_ns + 1, until_ns + 1)]


# -- the seam: Line wrappers -----------------------------------------------------------------
class _Hold(LineWrapper):
    """Drops the second chunk, doubles the third, holds the fourth back 1 ms."""

    def __init__(self) -> None:
        self.n = 0

    def send(self, start_ns, data, baud):
        self.n += 1
        return {2: (start_ns, b""), 3: (start_ns, data * 2), 4: (start_ns + 1_000_000, data)}.get(
            self.n, (start_ns, data))


def test_a_wrapper_changes_drops_and_delays_chunks_and_the_line_times_what_it_returns():
    line = Line("sins", Wire(115200), wrappers=[_Hold()])
    for k in range(4):
        line.put(k * SEC // 100, bytes([k]) * 10)
    one = wire_ns(10, 115200)
    assert sent(line) == [(0, one, b"\x00" * 10),
                          (2 * SEC // 100, 2 * SEC // 100 + wire_ns(20, 115200), b"\x02" * 20),
                          (3 * SEC // 100 + 1_000_000, 3 * SEC // 100 + 1_000_000 + one, b"\x03" * 10)]


def test_wrappers_apply_in_order_and_a_chunk_cannot_start_early():
    class Tag(LineWrapper):
        def __init__(self, b):
            self.b = b

        def send(self, start_ns, data, baud):
            return start_ns, data + self.b

    line = Line("sins", Wire(115200), wrappers=[Tag(b"1")])
    line.wrap(Tag(b"2"))
    line.put(0, b"x")
    assert sent(line)[0][2] == b"x12"

    class Early(LineWrapper):
        def send(self, start_ns, data, baud):
            return start_ns - 1, data

    line = Line("sins", Wire(115200), wrappers=[Early()])
    line.put(SEC, b"x")
    with pytest.raises(ValueError, match="earlier"):
        sent(line)


# -- the registry: a line-level kind, test-only --------------------------------------------
class _FlipBit(LineWrapper):
    def __init__(self, fault, rng) -> None:
        self.fault, self.rng, self.n = fault, rng, 0

    def send(self, start_ns, data, baud):
        self.n += 1
        if self.n % self.fault.every or not self.fault.active(start_ns):
            return start_ns, data
        i = int(self.rng.integers(len(data)))
        return start_ns, data[:i] + bytes([data[i] ^ 0x01]) + data[i + 1:]


@dataclass(frozen=True, kw_only=True)
class FlipBits(LineFault):
    """Flips the low bit of one byte of every Nth chunk on the port."""
    KIND = "test_flip_bits"
    every: int = key(3, "", "flip a bit of every Nth chunk", between(1, 1000))

    def wrapper(self, rng):
        return _FlipBit(self, rng)


@pytest.fixture
def flip_bits():
    register(FlipBits)
    yield FlipBits
    unregister(FlipBits.KIND)


def _record(tmp_path, sc, name):
    with Emulation(sc, 5, speed=None, ports=False, duration_s=1.0, record=tmp_path / name) as emu:
        emu.run()
    return Recording(tmp_path / name)


def test_a_line_fault_from_the_registry_wraps_its_port_and_no_other(tmp_path, flip_bits):
    plain = _record(tmp_path, variant(tmp_path, "office", "", "plain"), "plain")
    sc = variant(tmp_path, "office", '[[faults]]\nkind = "test_flip_bits"\nport = "sins"\n'
                                     "every = 4\nstart_s = 0.0\nend_s = 0.5\n", "flipped")
    assert sc.faults == (FlipBits(port="sins", every=4, start_s=0.0, end_s=0.5),)
    faulty = _record(tmp_path, sc, "flipped")
    a, b = list(plain.chunks("sins")), list(faulty.chunks("sins"))
    assert [(c.t_device_ns, len(c.data)) for c in a] == [(c.t_device_ns, len(c.data)) for c in b]
    changed = [n for n, (x, y) in enumerate(zip(a, b)) if x.data != y.data]
    assert changed == [n for n in range(3, len(a), 4) if a[n].t_device_ns < SEC // 2]
    assert all(sum(bin(p ^ q).count("1") for p, q in zip(a[n].data, b[n].data)) == 1
               for n in changed)
    for port in PORTS:
        if port != "sins":
            assert plain.read_bytes(port) == faulty.read_bytes(port), port


def test_a_line_fault_names_a_known_port_and_unregistered_kinds_are_refused(tmp_path, flip_bits):
    with pytest.raises(ScenarioError, match="port must be one of"):
        variant(tmp_path, "office", '[[faults]]\nkind = "test_flip_bits"\nport = "gps"\n'
                                    "start_s = 0.0\nend_s = 1.0\n")
    unregister(FlipBits.KIND)
    try:
        with pytest.raises(ScenarioError, match="kind must be one of"):
            variant(tmp_path, "office", '[[faults]]\nkind = "test_flip_bits"\nport = "sins"\n'
                                        "start_s = 0.0\nend_s = 1.0\n")
    finally:
        register(FlipBits)


def test_emulation_wrap_names_a_port(tmp_path):
    sc = variant(tmp_path, "office", "")
    with Emulation(sc, 1, speed=None, ports=False, duration_s=0.1) as emu:
        with pytest.raises(RunError, match="no port 'gps'"):
            emu.wrap("gps", LineWrapper())


def test_register_refuses_a_taken_kind_and_a_class_that_is_no_kind():
    @dataclass(frozen=True, kw_only=True)
    class Other(LineFault):
        KIND = "nlos"

    before = list(Fault.KINDS.names())
    with pytest.raises(FaultError, match="'nlos' is already registered"):
        register(Other)
    with pytest.raises(FaultError, match="not a DeviceFault or LineFault"):
        register(Fault)
    assert list(Fault.KINDS.names()) == before
    assert before[:len(SHIPPED)] == SHIPPED  # the shipped kinds, before any a user installed


def test_a_kind_from_an_installed_package_registers_through_its_entry_point(tmp_path, root):
    write(tmp_path, "toyfaults", "[navtwin.faults]\ntoy = toyfaults:Toy\n", {"toyfaults.py": """
        from dataclasses import dataclass
        from navtwin.emulator.faults import LineFault

        @dataclass(frozen=True, kw_only=True)
        class Toy(LineFault):
            KIND = "toy"
            def wrapper(self, rng):
                raise NotImplementedError
        """})
    out = subprocess.run(
        [sys.executable, "-c", "import json; from navtwin.emulator.faults import Fault; "
                               "print(json.dumps(list(Fault.KINDS.names())))"],
        capture_output=True, text=True, timeout=60,
        env={"PYTHONPATH": f"{root}:{tmp_path}", "PATH": ""})
    assert out.returncode == 0, out.stderr
    kinds = json.loads(out.stdout.splitlines()[0])
    assert kinds[:len(SHIPPED)] == SHIPPED and "toy" in kinds  # a user's other kinds may follow
