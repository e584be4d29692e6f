"""Batch twins of host.tracks: a track stepped for many seeds at once (issue 23's engine).

A batch track mirrors one host.tracks track, operation for operation, on the rows of the
seeds a step moves (``idx``): :class:`BatchTrack` is the interface, and each module holds
one twin, registered here by the name of the track it mirrors. The batch estimator
(host.batch.estimator) runs the tracks that have a twin; a track without one runs per seed
beside it (lab.batch), so every track has a result and a twin only makes it faster.
"""
from __future__ import annotations

from navtwin.protocols.plugins import Registry

from .base import BatchTrack, Columns

GROUP = "navtwin.batch_tracks"

#: track name -> its batch twin ("module:class", imported when used)
BATCH_TRACKS: Registry[type[BatchTrack]] = Registry(GROUP, "batch track", {
    "sins": "navtwin.host.batch.tracks.sins:BatchSinsTrack",
    "wsn": "navtwin.host.batch.tracks.wsn:BatchWsnTrack",
    "kf": "navtwin.host.batch.tracks.kf:BatchKfTrack",
    "ekf": "navtwin.host.batch.tracks.ekf:BatchEkfTrack",
    "ukf": "navtwin.host.batch.tracks.ukf:BatchUkfTrack",
    "lc": "navtwin.host.batch.tracks.lc:BatchLcTrack",
    "tc": "navtwin.host.batch.tracks.tc:BatchTcTrack",
    "fatci": "navtwin.host.batch.tracks.fatci:BatchFatciTrack",
})
get = BATCH_TRACKS.get


def batchable(filters) -> tuple[str, ...]:
    """The names among *filters* that have a batch twin, in their order."""
    return tuple(f for f in filters if f in BATCH_TRACKS)


__all__ = ["BATCH_TRACKS", "BatchTrack", "Columns", "batchable", "get"]
