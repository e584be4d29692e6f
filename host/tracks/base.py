"""The interface of a fusion track: one output stream of estimates (docs/filters.md).

A track is a class with a ``name`` (its ``filter`` in the output and its section
``[filters.<name>]`` in the host config), a ``Settings`` frozen dataclass declared with
:func:`navtwin.common.schema.key` (units, docs, checks: the config reads and documents it), and:

* :meth:`handlers`: which records (host.measurements: ImuSample, Exchange, ...) and shared
  products (Motion, Range, Tdoa, Fix, FixRefused: host.measurements) it takes, each with the method
  that takes it; the estimator calls these in time order;
* :meth:`estimate`: what it emits at an output instant (an Estimate, or None before it has
  one), with ``extrapolated`` set from its last aiding;
* :meth:`restart`: its reset when a device restarts (a discontinuity), counted with
  :meth:`count_reinit`; :meth:`gap` likewise after a gap in the IMU stream too long to bridge; a track that starts again from a WSN fix sets ``reinit_since``;
* its stats: ``updates`` and ``rejections`` (Counters by kind or reason) and ``reinits``.

The estimator (``est``) owns what several tracks share: the time base (``est.t``), the
output instants, the alignment and the strapdown (``est.sins``, ``est.aligned``), the WSN
fixes (``est.fixes``), the motion model and the shared settings (``est.cfg``).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, ClassVar

import numpy as np

if TYPE_CHECKING:
    from navtwin.host.estimator import Estimator


@dataclass(frozen=True, slots=True)
class Estimate:
    """One track's estimate at an output instant (docs/filters.md, host.output)."""

    t: float
    filter: str
    x: float
    y: float
    vx: float
    vy: float
    yaw: float | None
    cov: list[float]  # 4x4 covariance of (x, y, vx, vy), row-major
    extrapolated: bool = False  # the track had no aiding for extrapolated_after_s before t
    vehicle: int = 1  # the lab's vehicle (host config, numbered from 1); the estimator sets it


def estimate(t, name, p, v, yaw, cov4, extrapolated: bool) -> Estimate:
    """p, v: sequences of 2; cov4: a 4x4 array, or its 16 floats row-major."""
    (x, y), (vx, vy) = np.asarray(p, float).tolist(), np.asarray(v, float).tolist()
    cov = cov4 if isinstance(cov4, list) else np.ravel(cov4).tolist()
    return Estimate(float(t), name, x, y, vx, vy, None if yaw is None else float(yaw), cov,
                    bool(extrapolated))


@dataclass(frozen=True)
class NoSettings:
    """A track without settings of its own."""


class Track:
    name: ClassVar[str]
    Settings: ClassVar[type] = NoSettings
    #: Uses the strapdown (so the estimator runs it after the alignment) and its yaw.
    uses_strapdown: ClassVar[bool] = False
    #: Takes updates, so its stats report updates and rejections.
    aided: ClassVar[bool] = True

    def __init__(self, est: Estimator, settings=None) -> None:
        self.est = est
        self.settings = self.Settings() if settings is None else settings
        self.updates: Counter = Counter()
        self.rejections: Counter = Counter()
        self.reinits: Counter = Counter()

    def handlers(self) -> dict[type, Callable]:
        """Record or product type -> the method that takes it."""
        return {}

    def start(self, t: float) -> None:
        """The first measurement of the run, at t."""

    def restart(self, device: str, t: float) -> None:
        """``device`` restarted at t: what the track holds need not be where the vehicle is."""

    def gap(self, t: float) -> None:
        """The IMU stream had a gap longer than ``imu_gap_s`` before t, which the strapdown
        did not bridge (host.estimator)."""

    #: Set to the time of a discontinuity by a track that starts again from the first WSN
    #: fix newer than it: the estimator then calls :meth:`reinit_at` with that fix.
    reinit_since: float | None = None

    def reinit_at(self, fix) -> None:
        """Start again at *fix* (a host.measurements.Fix) and clear ``reinit_since``."""
        raise NotImplementedError

    @property
    def pending(self) -> bool:
        """Waiting to re-initialise."""
        return self.reinit_since is not None

    def estimate(self, b: float, yaw: float) -> Estimate | None:
        raise NotImplementedError

    def count_reinit(self, cause: str) -> None:
        self.reinits[cause] += 1
        self.est.reinit_count += 1
