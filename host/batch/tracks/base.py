"""The interface of a batch track (host.tracks.base.Track for the rows of many seeds).

A batch track is built with the batch estimator (its context: ``cfg``, the time base's
arrays ``t`` and ``t_first``, the strapdown, the fixes) and the track's
settings, and gives:

* :meth:`handlers`: product type (host.measurements.Motion, Fix, FixRefused) -> the method
  that takes a batch of them, ``fn(idx, batch)`` with the rows *idx* of the seeds that
  have one (host.batch.estimator's MotionBatch, FixBatch);
* :meth:`start`: as Track's, for the seeds *idx*;
* :meth:`estimate`: the :class:`Columns` of the seeds *idx* at their output instants.

A track with a strapdown of its own (``own_strapdown``) is given it by the estimator as
``nav`` (a host.batch.strapdown.BatchStrapdown), rows of one stack the estimator steps with
each IMU sample in one call for all the strapdowns of the batch; :meth:`own_step` tells it
which seeds' own strapdown steps with the sample and over what dt.

A track whose state is the constant-acceleration model's (``ca_state``: ``x`` (n, 6), ``P``
(n, 6, 6) and ``t_predicted`` (n,), host.batch.tracks.fusion's) has them as rows of one stack
the estimator gives it, which predicts every such track's seeds to the filter time in one
call before it gives them a Motion product (what each track's sync would do).

A seed whose track would take a branch the twin does not carry (a numerical reset, a
discontinuity the twin does not follow) is handed back with :meth:`BatchEstimator.eject`: the
engine runs it again per seed, so a twin need not carry the rare branches.
"""
from __future__ import annotations

from typing import Callable, ClassVar, NamedTuple

import numpy as np


class Columns(NamedTuple):
    """Estimates of some seeds at their output instants (host.tracks.base.Estimate's fields,
    one row each): ``valid`` says which rows have one (a track may have none yet)."""
    valid: np.ndarray  # (n,) bool
    x: np.ndarray  # (n, 2) position, m
    v: np.ndarray  # (n, 2) velocity, m/s
    cov: np.ndarray  # (n, 4, 4) of (x, y, vx, vy)
    stale: np.ndarray  # (n,) bool: extrapolated
    has_yaw: bool  # the track reports a yaw (else None)
    yaw: np.ndarray | None = None  # (n,) its own (a strapdown of its own); None: the estimator's


class BatchTrack:
    name: ClassVar[str]
    uses_strapdown: ClassVar[bool] = False
    own_strapdown: ClassVar[bool] = False
    ca_state: ClassVar[bool] = False

    def __init__(self, ctx, settings=None) -> None:
        self.ctx = ctx
        self.settings = settings

    def handlers(self) -> dict[type, Callable]:
        return {}

    def own_step(self, idx: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Of the seeds *idx* with an IMU sample at t: which step their own strapdown with it
        (a mask), and over what dt (one per such seed). Only with ``own_strapdown``."""
        raise NotImplementedError

    def start(self, idx: np.ndarray, t: np.ndarray) -> None:
        """The first measurement of the seeds *idx*, at t."""

    def estimate(self, idx: np.ndarray, b: np.ndarray) -> Columns:
        raise NotImplementedError
