"""Short emulator recordings for the diff tests, and copies of them with damage made on purpose."""
import shutil
from pathlib import Path

from navtwin.protocols.recording import INDEX_HEADER, Recording

from .helpers import navtwin


def office(directory: Path, seed: int) -> Path:
    """A 2 s office run of seed *seed* recorded into *directory* (its links in a directory
    of its own beside it: the default one may be another emulator's)."""
    p = navtwin("emulate", "--scenario", "office", "--speed", "max", "--duration", 2,
                "--seed", seed, "--record", directory, "--link-dir", f"{directory}.links")
    assert p.returncode == 0, p.stderr
    return directory


def copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def flip_bit(directory: Path, port: str, offset: int, bit: int = 0) -> None:
    """Flip one bit of byte *offset* of the port's data (its index stays true)."""
    path = directory / f"{port}.bin"
    data = bytearray(path.read_bytes())
    data[offset] ^= 1 << bit
    path.write_bytes(bytes(data))


def cut_chunk(directory: Path, port: str, index: int) -> bytes:
    """Remove the port's chunk *index* (its bytes and its index line, the later offsets
    moved up, as if the device never wrote it); its bytes."""
    chunks = list(Recording(directory).chunks(port))
    cut = chunks.pop(index)
    lines, offset = [INDEX_HEADER], 0
    for c in chunks:
        lines.append(f"{offset},{len(c.data)},{c.t_device_ns},"
                     f"{'' if c.t_wall_ns is None else c.t_wall_ns}")
        offset += len(c.data)
    (directory / f"{port}.bin").write_bytes(b"".join(c.data for c in chunks))
    (directory / f"{port}.csv").write_text("\n".join(lines) + "\n")
    return cut.data


def compared_runs(base: Path) -> dict[str, Path]:
    """Seeds 1, 2 and 1 again, each a 2 s office run in *base*: what the diff tests compare."""
    return {name: office(base / name, seed) for name, seed in (("one", 1), ("two", 2), ("again", 1))}
