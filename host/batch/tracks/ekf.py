"""``ekf``'s twin (host.tracks.ekf): the KF's prediction and acceleration update, each
cycle's range differences (``tight = "tdoa"``) or each range (``"toa"``) linearised at the
prior: host.batch.tracks.fusion's Joseph update through host.batch.model.BatchRanges."""
from __future__ import annotations

from .fusion import BatchTightTrack


class BatchEkfTrack(BatchTightTrack):
    name = "ekf"
