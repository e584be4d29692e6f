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

import io
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


_FMT = ["%d"] + ["%.6f"] * 9 + ["%.9f"] * 6


def csv_rows(arr: np.ndarray) -> bytes:
    """truth.csv's rows for *arr*: the rows of a file do not depend on how it was cut up, so
    a run can append them as it goes."""
    if not len(arr):
        return b""
    out = io.StringIO()
    # float64 holds integer ns exactly up to 104 days
    np.savetxt(out, np.column_stack([arr[f] for f in FIELDS]), fmt=_FMT, delimiter=",")
    return out.getvalue().encode("ascii")


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
