"""Truth: the vehicle's true state on a 1 kHz grid, and truth.csv.

Fields (navigation frame: x, y of the area, z up; body x forward, y left, z up):

=========  =======  ==========================================================
t          ns       true time, integer, a multiple of 1 ms
x y z      m        position of the vehicle's reference point (IMU and tag antenna)
vx vy vz   m/s      velocity
ax ay az   m/s^2    kinematic acceleration (gravity not included)
roll       rad      Z-Y-X Euler angles; the vehicle stays level on the floor
pitch      rad
yaw        rad      (-pi, pi], 0 = body x along +x, counter-clockwise positive
wx wy wz   rad/s    body angular rate relative to the navigation frame
=========  =======  ==========================================================

truth.csv has a header row with these names and one row per millisecond.
"""
from __future__ import annotations

import os

import numpy as np

STEP_NS = 1_000_000
FIELDS = ("t", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "roll", "pitch", "yaw", "wx", "wy", "wz")
DTYPE = np.dtype([("t", np.int64)] + [(f, np.float64) for f in FIELDS[1:]])


def truth_arrays(trajectory, t0_ns: int, t1_ns: int) -> np.ndarray:
    """Structured array of the true state at every whole millisecond in [t0_ns, t1_ns)."""
    first = -(-t0_ns // STEP_NS) * STEP_NS
    t = np.arange(first, t1_ns, STEP_NS, dtype=np.int64)
    out = np.empty(len(t), dtype=DTYPE)
    out["t"] = t
    if not len(t):
        return out
    k = trajectory.kinematics(t)
    for i, axis in enumerate("xyz"):
        out[axis] = k.pos[:, i]
        out["v" + axis] = k.vel[:, i]
        out["a" + axis] = k.acc[:, i]
        out["w" + axis] = k.rate[:, i]
    out["roll"], out["pitch"], out["yaw"] = k.roll, k.pitch, k.yaw
    return out


HEADER = (",".join(FIELDS) + "\n").encode("ascii")


def file_name(vehicle: int = 1) -> str:
    """The recording's truth file of vehicle *vehicle*: truth.csv, then truth2.csv, ... (as
    its ports are named, protocols.ports)."""
    return "truth.csv" if vehicle == 1 else f"truth{vehicle}.csv"


#: digits after the point of each field: t an integer ("%d"), metres and their rates "%.6f",
#: angles and rates "%.9f" (csv_rows makes 6 and 9: two or three groups of three)
PLACES = (0,) + (6,) * 9 + (9,) * 6
_LINE = ",".join("%d" if p == 0 else f"%.{p}f" for p in PLACES) + "\n"  # one row, as printf


def _words() -> np.ndarray:
    """The 4-byte words truth.csv's text is made of, NUL-padded on the left (the NULs are
    deleted at the end), in sections of 1000 (one word per group g of three digits)."""
    sections = [b"%03d", b"%d", b"-%d", b".%03d", b"%03d,", b"%03d\n"]
    words = [f % g for f in sections for g in range(1000)] + [b",", b""]
    return np.frombuffer(b"".join(w.rjust(4, b"\0") for w in words), np.uint32)


_WORDS = _words()
# where each section starts in _WORDS: a group after an integer's first, an integer's first
# group, a negative one's, a fraction's first group with its point, a last group with the
# comma after it, or with the row's end
GROUP, FIRST, NEGATIVE, POINT, COMMA, NEWLINE = range(0, 6000, 1000)
SEPARATOR, NOTHING = 6000, 6001  # a lone comma; no text


def _integer_words(k: np.ndarray, negative: np.ndarray) -> np.ndarray:
    """The words of each integer *k* >= 0 (a minus sign where *negative*): (..., G) indices
    into _WORDS, G groups of three digits for the largest, the others NOTHING-padded."""
    groups = max(1, -(-len(str(int(k.max()))) // 3))
    power = 1000 ** np.arange(groups - 1, -1, -1, dtype=np.int64)
    digits = k[..., None] // power % 1000  # groups of three, the first most significant
    used = 1 + (k[..., None] >= power[:-1]).sum(-1)  # the groups this integer's text has
    slot = np.arange(groups) - (groups - used)[..., None]  # 0: its first group
    return np.where(slot > 0, GROUP + digits,
                    np.where(slot == 0, FIRST + (NEGATIVE - FIRST) * negative[..., None] + digits,
                             NOTHING))


def csv_rows(arr: np.ndarray) -> bytes:
    """truth.csv's rows for *arr*: the rows of a file do not depend on how it was cut up, so
    a run can append them as it goes.

    The text is printf's (``_LINE``: "%d" of t, "%.6f"/"%.9f" of the rest: the value's exact
    binary fraction correctly rounded, halves to even), made with whole-array numpy steps
    rather than a format call per number: y = |x| 10^p is one rounding from the exact
    product, so rint(y) is printf's digits unless the exact product can be a half (y within
    y 2^-52 >= ulp(y) of one; rows holding such a value, or a value too large or not finite,
    are printed by printf itself). Each number becomes 4-byte words of three digits (_WORDS), taken in
    one step."""
    if len(arr) > _ROWS:
        return b"".join(csv_rows(arr[i:i + _ROWS]) for i in range(0, len(arr), _ROWS))
    if not len(arr):
        return b""
    values = np.column_stack([arr[f] for f in FIELDS[1:]])
    places = np.array(PLACES[1:])
    scale = 10.0 ** places
    y = np.abs(values) * scale
    scaled = np.rint(y)
    with np.errstate(invalid="ignore"):  # nan and inf: unsure
        # y 2^-52 >= ulp(y); 0.5 - |y - rint(y)| is exact where it is under 0.25
        unsure = ~(0.5 - np.abs(y - scaled) > y * 2.0 ** -52) | ~(y < 2.0 ** 50)
    if unsure.any():
        rows = np.flatnonzero(unsure.any(axis=1))
        cuts = zip(np.r_[0, rows + 1], np.r_[rows, len(arr)])
        return b"".join(csv_rows(arr[lo:hi]) + (_LINE % tuple(arr[hi].tolist())).encode("ascii")
                        if hi < len(arr) else csv_rows(arr[lo:hi]) for lo, hi in cuts)
    # whole-number arithmetic in float64 (exact below 2^50, and faster than int64 division)
    whole = np.floor(scaled / scale)
    fraction = (scaled - whole * scale) * 10.0 ** (9 - places)  # as nine places
    t = arr["t"]
    lead = _integer_words(np.abs(t), t < 0)
    x = _integer_words(whole.astype(np.int64), np.signbit(values))
    n, fields, g = x.shape
    row = np.empty((n, lead.shape[1] + 1 + fields * (g + 3)), np.intp)
    row[:, :lead.shape[1]] = lead
    row[:, lead.shape[1]] = SEPARATOR
    words = row[:, lead.shape[1] + 1:].reshape(n, fields, g + 3)
    words[..., :g] = x
    nine = places == 9  # "%.9f": three groups after the point; "%.6f": two
    end = np.full(len(places), COMMA)
    end[-1] = NEWLINE
    for i, section in enumerate((POINT, np.where(nine, GROUP, end), np.where(nine, end, 0))):
        unit = 1000.0 ** (2 - i)  # three digits at a time, the first most significant
        digits = np.floor(fraction / unit)
        fraction -= digits * unit
        words[..., g + i] = section + digits
    words[:, ~nine, g + 2] = NOTHING
    return _WORDS.take(row).tobytes().translate(None, b"\0")


#: rows formatted at a time: a few hundred keep the temporaries small and warm (in a run, a
#: second's 1000 at once took a quarter longer: fresh memory between the world's blocks)
_ROWS = 400


def write_truth_csv(path: str | os.PathLike, world_or_arrays, chunk_s: float = 10.0) -> int:
    """Write truth.csv from a World (its whole run) or from truth arrays; returns the rows."""
    if isinstance(world_or_arrays, np.ndarray):
        parts = [world_or_arrays]
    else:
        w = world_or_arrays
        step = round(chunk_s * 1e9)
        parts = (w.truth(t, min(t + step, w.duration_ns)) for t in range(0, w.duration_ns, step))
    rows = 0
    with open(path, "wb") as fh:
        fh.write(HEADER)
        for arr in parts:
            fh.write(csv_rows(arr))
            rows += len(arr)
    return rows


def read_truth_csv(path: str | os.PathLike) -> np.ndarray:
    """truth.csv back as the structured array."""
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    out = np.empty(len(data), dtype=DTYPE)
    for i, f in enumerate(FIELDS):
        out[f] = data[:, i]
    return out
