"""Helpers for the physics tests: scenario variants, whole runs, decoding the bytes back.

Decoding goes through protocols' streaming decoders, the same path the host uses, so the
tests check the bytes on the wire, not the emulator's internal numbers.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from navtwin.emulator.faults import Fault
from navtwin.emulator.scenario import load_scenario
from navtwin.emulator.world import World
from navtwin.protocols import adis16350 as adis
from navtwin.protocols.nanoloc import SPEED_OF_LIGHT
from navtwin.protocols.stream import Frame, nanoloc_decoder, sins_decoder


def variant(tmp_path: Path, base: str, toml: str, name: str = "variant") -> object:
    """A scenario that starts from *base* and overrides what *toml* says."""
    path = tmp_path / f"{name}.toml"
    path.write_text(f'base = "{base}"\nname = "{name}"\n{toml}', encoding="utf-8")
    return load_scenario(path)


def made_together(tmp_path: Path, base: str, toml: str | None, other: str, port: str) -> list:
    """The events before 2.5 s of seeds 1, 2 and 7 of *base* (with *toml*'s overrides) and of
    seed 3 of scenario *other*, made by World.make_together, asserted equal to each world's
    made alone; each seed's *port* events differ from the next seed's (its own draws)."""
    sc = variant(tmp_path, base, toml, "together") if toml else load_scenario(base)
    worlds = [(sc, 1), (sc, 2), (sc, 7), (load_scenario(other), 3)]
    until = 2_500_000_000
    alone = [World(w_sc, s).advance(until) for w_sc, s in worlds]
    together = [World(w_sc, s) for w_sc, s in worlds]
    World.make_together(together, until)
    made = [w.advance(until) for w in together]
    assert made == alone
    data = [[e.data for e in events if e.port.startswith(port)] for events in made]
    assert data[0] and data[0] != data[1]
    return made


def run(sc, seed: int | None = None) -> tuple[World, list]:
    w = World(sc, seed)
    return w, w.advance(w.duration_ns)


def port_bytes(events, port: str) -> bytes:
    return b"".join(e.data for e in events if e.port == port)


def sins(events, gyro_range: int = 300) -> dict:
    """Decoded SINS frames: t_ns (write start), seq, words (N, 11) and SI arrays."""
    t = np.array([e.t_ns for e in events if e.port == "sins"], dtype=np.int64)
    frames = [f for f in sins_decoder().decode(port_bytes(events, "sins"))]
    assert all(isinstance(f, Frame) for f in frames), "the SINS stream must decode cleanly"
    words = np.array([f.fields["words"] for f in frames], dtype=np.int64)
    out = adis.words_to_arrays(words, gyro_range)
    out.update(t_ns=t, seq=np.array([f.fields["seq"] for f in frames]), words=words)
    return out


def reports(events) -> dict:
    """Decoded gateway reports as arrays, with both distances of the taus."""
    frames = nanoloc_decoder().decode(port_bytes(events, "nanoloc"))
    assert all(isinstance(f, Frame) for f in frames), "the nanoLOC stream must decode cleanly"
    f = [x.fields for x in frames]
    tau = np.array([x["tau"] for x in f], dtype=np.int64).reshape(-1, 4)
    ps = 1e-12 * SPEED_OF_LIGHT
    return {
        "t_ns": np.array([e.t_ns for e in events if e.port == "nanoloc"], dtype=np.int64),
        "seq": np.array([x["seq"] for x in f]), "t_us": np.array([x["t_us"] for x in f], dtype=np.int64),
        "anchor": np.array([x["anchor"] for x in f]), "tag": np.array([x["tag"] for x in f]),
        "status": np.array([x["status"] for x in f]), "rssi": np.array([x["rssi"] for x in f]),
        "tau": tau,
        "d": ps * (tau[:, 0] - tau[:, 1] + tau[:, 2] - tau[:, 3]) / 4,  # wire-formats.md section 3
        "d_single": ps * (tau[:, 0] - tau[:, 1]) / 2,
    }


def true_distances(world, sc, rep: dict) -> np.ndarray:
    """3-D truth distance tag-anchor at each report's exchange time (t_us on the network
    clock), from the world's 1 kHz truth."""
    true_ns = rep["t_us"] * 1000 / (1 + sc.clocks.network_ppm * 1e-6)
    truth = world.truth(0, world.duration_ns)
    pos = np.column_stack([np.interp(true_ns, truth["t"], truth[c]) for c in "xyz"])
    anchors = {a.id: sc.anchor_position(a) for a in sc.anchors}
    apos = np.array([anchors[a] for a in rep["anchor"]])
    return np.linalg.norm(pos - apos, axis=1)
