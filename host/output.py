"""What the host writes.

Estimates: one JSON object per line, keys in this order, numbers as Python's ``repr``
(``json.dumps``), so equal estimates give equal bytes::

    {"t":12.34,"vehicle":1,"filter":"ukf","x":6.01,"y":1.79,"vx":0.0,"vy":0.0,"yaw":0.0,"cov":[[...],...],
     "extrapolated":false}

``t`` is host time in seconds since the run started (docs/host.md); ``vehicle`` the
vehicle's number in the host config (1 in a lab with one vehicle); ``yaw`` is null for
the pure WSN track; ``cov`` is the estimator's covariance of (x, y, vx, vy), row-major;
``extrapolated`` is true when the track had no aiding for the estimator's
``extrapolated_after_s`` before ``t`` (a position update for kf/ekf/ukf, a fix for wsn, an
IMU sample for sins), or the track waits to re-initialise: the estimate is a prediction only.
With ``[output] geodetic = true`` in the host config, ``"lat"``, ``"lon"`` (deg, WGS-84) and
``"h"`` (m, ellipsoid height) follow ``"y"``: the estimate's x, y on the floor (z = 0) through
the area's frame on the earth (common.geodesy.LocalFrame of [site] and [filters]
x_azimuth_deg), so ``LocalFrame.local(lat, lon, h)`` gives back x, y, 0; off, the line is as
above, byte for byte.
Innovations (opt-in, ``navtwin host --innovations FILE``): one JSON line per gated update of
a fusion track, :func:`innovation_line`; writing them changes no estimate.
Status, progress and summary lines go to stderr as one JSON
object each, ``{"status": {...}}``, ``{"progress": {...}}``, ``{"summary": {...}}``; they
carry wall-clock figures (rates, latency) and are not part of the deterministic output.
"""
from __future__ import annotations

import json
import sys
from collections import deque
from typing import TextIO

import numpy as np

from navtwin.common.geodesy import LocalFrame

KEYS = ("t", "vehicle", "filter", "x", "y", "vx", "vy", "yaw", "cov", "extrapolated")


#: The keys ``[output] geodetic`` adds after ``"y"``.
GEODETIC_KEYS = ("lat", "lon", "h")


def estimate_line(e, frame: LocalFrame | None = None) -> str:
    """The output line of one :class:`navtwin.host.estimator.Estimate`; with the area's
    *frame* (HostConfig.output_frame), its geodetic position too."""
    geo = {}
    if frame is not None:
        geodetic = frame.geodetic((float(e.x), float(e.y), 0.0))
        geo = dict(zip(GEODETIC_KEYS, map(float, geodetic)))
    return json.dumps({"t": float(e.t), "vehicle": int(e.vehicle), "filter": str(e.filter), "x": float(e.x), "y": float(e.y),
                       **geo, "vx": float(e.vx), "vy": float(e.vy),
                       "yaw": None if e.yaw is None else float(e.yaw),
                       "cov": np.asarray(e.cov, dtype=float).tolist(),
                       "extrapolated": bool(e.extrapolated)},
                      separators=(",", ":")) + "\n"


INNOVATION_KEYS = ("t", "vehicle", "filter", "kind", "dim", "nis", "accepted")


def innovation_line(t: float, vehicle: int, filter: str, kind: str, dim: int, nis: float,
                    accepted: bool) -> str:
    """The line of one gated fusion update (``navtwin host --innovations``): its time (the
    measurement's, host time), kind ("accel", "fix", "tdoa", "range"...), the measurement's
    dimension, NIS = y^T S^-1 y and whether it passed the chi-square gate."""
    return json.dumps(dict(zip(INNOVATION_KEYS, (float(t), int(vehicle), str(filter), str(kind),
                                                 int(dim), float(nis), bool(accepted)))),
                      separators=(",", ":")) + "\n"


def info_line(kind: str, body: dict) -> str:
    """A status / progress / summary line for stderr."""
    return json.dumps({kind: body}, separators=(",", ":"), default=str) + "\n"


def open_output(spec: str) -> TextIO:
    """``-`` is stdout; anything else a file, created or truncated."""
    if spec == "-":
        return sys.stdout
    return open(spec, "w", encoding="utf-8")


class Latency:
    """Processing latencies in ns: percentiles of the current status period and of the run."""

    def __init__(self, keep: int = 100_000) -> None:
        self._period: list[int] = []
        self._all: deque[int] = deque(maxlen=keep)

    def add(self, ns: int) -> None:
        self._period.append(ns)
        self._all.append(ns)

    def period(self) -> dict:
        """Since the last call."""
        out, self._period = percentiles_ms(self._period), []
        return out

    def overall(self) -> dict:
        return percentiles_ms(self._all)


def percentiles_ms(ns) -> dict:
    """Count, p50, p99 and max (ms, to the microsecond) of latencies in ns."""
    if not len(ns):
        return {"n": 0}
    ms = np.asarray(ns, dtype=float) / 1e6
    p50, p99 = np.percentile(ms, [50, 99])
    return {"n": int(ms.size), "p50_ms": round(float(p50), 3), "p99_ms": round(float(p99), 3),
            "max_ms": round(float(ms.max()), 3)}
