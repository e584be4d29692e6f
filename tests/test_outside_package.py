"""An outside package extends the lab with no edit of navtwin: a port (a magnetometer board:
its declaration, wire format, decoder and device model), a fusion track and a fault kind, all
through entry points, as an installed package would (docs/architecture.md, "A port").

The package is written to a folder with a dist-info whose entry_points.txt declares them; a
separate navtwin process, with the folder on its path, emulates a short run (the new port gets
its PTY, line and recording like the lab's), decodes the new port's recording, and replays the
run through the host's pipeline with the new track.
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

from .helpers import navtwin
from .packages import write

#: the package, one module per extension point (a module that imports emulator.faults must
#: not be the one that declares the package's fault kind: importing emulator.faults loads it)
MAGLAB = {
    "__init__.py": '"""A magnetometer board on a fourth port: frames ``4D 47 seq:u16 heading:u16``'
                   ' (0.1 deg) every 100 ms."""\n',
    "port.py": '''
        import struct
        from collections import Counter

        from navtwin.protocols.formats import Format
        from navtwin.protocols.ports import Port
        from navtwin.protocols.stream import DecodeError, Frame

        SYNC, SIZE = b"MG", 6

        PORT = Port("mag", "mag", "mag-board", "the magnetometer board's heading frames",
                    baud=9600, order=3, host_order=3)


        class MagDecoder:
            format = "mag"

            def __init__(self):
                self.buf, self.base, self.bytes, self.frames = bytearray(), 0, 0, 0
                self.errors = Counter()

            def feed(self, data):
                self.bytes += len(data)
                self.buf += data
                out = []
                while (i := self.buf.find(SYNC)) >= 0 and len(self.buf) - i >= SIZE:
                    if i:
                        out.append(DecodeError("garbage", self.base, i, self.format))
                        self.errors["garbage"] += 1
                    raw = bytes(self.buf[i:i + SIZE])
                    seq, heading = struct.unpack(">HH", raw[2:])
                    out.append(Frame(self.format, self.base + i, raw, 1,
                                     {"seq": seq, "heading_deg": heading / 10}))
                    self.frames += 1
                    del self.buf[:i + SIZE]
                    self.base += i + SIZE
                return out

            def flush(self):
                return []

            def summary(self):
                return {"format": self.format, "frames": self.frames, "bytes": self.bytes,
                        "errors": dict(self.errors)}


        FORMAT = Format("mag", MagDecoder, "the magnetometer board's frames")
        ''',
    "device.py": '''
        import struct

        from navtwin.emulator.devices import Device
        from navtwin.emulator.world import Event

        from .port import SYNC

        PERIOD_NS = 100_000_000


        class MagBoard(Device):
            """The board turns slowly: 0.7 deg a frame."""

            def __init__(self, emulation, port):
                super().__init__(emulation, port)
                self.end_ns, self.next_ns, self.seq = emulation.world.duration_ns, 0, 0

            def advance(self, until_ns):
                out = []
                while self.next_ns < min(until_ns, self.end_ns):
                    frame = SYNC + struct.pack(">HH", self.seq, self.seq * 7 % 3600)
                    out.append(Event(self.next_ns, self.port.name, frame))
                    self.seq, self.next_ns = self.seq + 1, self.next_ns + PERIOD_NS
                return out
        ''',
    "track.py": '''
        from navtwin.host.tracks import Estimate, Track


        class HeadingTrack(Track):
            """Reports the strapdown's heading at the lab's origin."""
            name = "heading"
            aided = False

            def estimate(self, b, yaw):
                return Estimate(b, self.name, 0.0, 0.0, 0.0, 0.0, yaw, [0.0] * 16)
        ''',
    "fault.py": '''
        from dataclasses import dataclass

        from navtwin.emulator.faults import LineFault
        from navtwin.emulator.faults.line import FaultWrapper


        @dataclass(frozen=True, kw_only=True)
        class Hush(LineFault):
            """The line goes quiet: every chunk of an episode is lost."""
            KIND = "hush"

            def wrapper(self, rng):
                return _Hush(self, rng)


        class _Hush(FaultWrapper):
            def act(self, start_ns, data, baud):
                self.mark(start_ns, 0, 0, removed=len(data))
                return start_ns, b""
        ''',
}

ENTRY_POINTS = """\
[navtwin.ports]
mag = maglab.port:PORT

[navtwin.formats]
mag = maglab.port:FORMAT

[navtwin.devices]
mag-board = maglab.device:MagBoard

[navtwin.tracks]
heading = maglab.track:HeadingTrack

[navtwin.faults]
hush = maglab.fault:Hush
"""


def install(tmp_path: Path) -> dict:
    """The package in *tmp_path*; the environment of a process that has it installed."""
    return write(tmp_path, "maglab", ENTRY_POINTS, {f"maglab/{name}": text for name, text in MAGLAB.items()})


def run(env: dict, *argv) -> subprocess.CompletedProcess:
    p = navtwin(*argv, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    return p


def test_a_package_adds_a_port_with_its_decoder_a_track_and_a_fault_kind(tmp_path):
    env = install(tmp_path / "pkg")
    rec = tmp_path / "rec"
    # the magnetometer's line is quiet from 1 s to 1.5 s: five frames lost
    run(env, "emulate", "--scenario", "office", "--seed", "7", "--speed", "max",
            "--duration", "3", "--record", rec, "--fault", "hush:port=mag,start_s=1,end_s=1.5")
    meta = json.loads((rec / "recording.json").read_text())
    assert set(meta["ports"]) == {"sins", "xbee", "nanoloc", "mag"}
    assert meta["ports"]["mag"] == {"baud": 9600}  # the declaration's rate: no scenario key
    faults = [json.loads(line) for line in (rec / "faults.jsonl").read_text().splitlines()]
    assert {f["kind"] for f in faults} == {"hush"} and len(faults) == 5

    # navtwin decode reads the port's recording with its format (found from the declaration)
    lines = [json.loads(line) for line in run(env, "decode", rec, "--format", "mag")
             .stdout.splitlines()]
    frames = [r for r in lines if "seq" in r]
    assert [r["seq"] for r in frames] == [s for s in range(30) if not 10 <= s < 15]
    assert frames[1] == {"format": "mag", "offset": 6, "type": 1, "seq": 1, "heading_deg": 0.7}
    assert lines[-1]["summary"]["frames"] == 25

    # the host reads the port (its decoder, its frames counted) and runs the package's track
    out = tmp_path / "est.jsonl"
    p = run(env, "replay", rec, "--config", "office", "--filters", "sins,heading",
                "--out", out)
    summary = json.loads(p.stderr.strip().splitlines()[-1])["summary"]
    assert summary["ports"]["mag"] == {"bytes": 150, "frames": 25, "errors": {}}
    assert summary["counts"]["mag_frames"] == 25
    estimates = [json.loads(line) for line in out.read_text().splitlines()]
    assert {e["filter"] for e in estimates} == {"sins", "heading"}
    # and the live host takes the port as an input of its own
    assert "--mag PORT" in run(env, "host", "--help").stdout
