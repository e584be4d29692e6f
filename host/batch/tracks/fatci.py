"""``fatci``'s twin (host.tracks.fatci): tc's (host.batch.tracks.tc) with each range's R set
by the fuzzy system from sigma(rho_WSN) (001 Algorithm 1, eq. 31: the per-seed track's
table, interpolated for every row at once)."""
from __future__ import annotations

from navtwin.host.tracks.fatci import FatciTrack

from .tc import BatchTcTrack


class BatchFatciTrack(BatchTcTrack):
    name = "fatci"
    Track = FatciTrack
