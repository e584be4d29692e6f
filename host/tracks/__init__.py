"""Fusion tracks, one module each, registered by name (docs/filters.md).

Built in, in output order: ``sins``, ``wsn``, ``kf``, ``ekf``, ``ukf`` (000's), ``lc``,
``tc``, ``fatci`` (001's), ``centroid``, ``wcl``, ``geosins`` (003's) and ``kf-rel``,
``hinf``, ``hinf+lssvm``, ``hinf+bp`` (004's; hinf's need the ``lmi`` extra). A track of a user's
package is added with :func:`register` (in process), or by an entry point in the group
``navtwin.tracks`` whose name is the track's name and whose object is its class::

    [project.entry-points."navtwin.tracks"]
    mine = "mypkg.tracks:MyTrack"

Registered tracks follow the built-in ones in output order, in the order they were added
(entry points by name). ``--filters all`` and ``[filters] enabled`` accept every name.
"""
from __future__ import annotations

from navtwin.protocols.plugins import Registry

from .base import Estimate, NoSettings, Track

#: What runs when no filters are named: 000's tracks. 001's error-state tracks (lc, ...) run
#: when named (``--filters``, ``[filters] enabled``): together they add about 0.6 of the
#: five's replay time (docs/lab.md, "Replay with all eight tracks"); 003's (centroid, wcl,
#: geosins) likewise (not yet in that measurement).
DEFAULT = ("sins", "wsn", "kf", "ekf", "ukf")
#: 000's and 001's tracks: those with a batch twin (host.batch), a sweep's default and the set
#: issue 23's speed figures take (navtwin bench sweep, host-replay)
EIGHT = DEFAULT + ("lc", "tc", "fatci")
GROUP = "navtwin.tracks"


def _check(name: str, cls) -> None:
    if not (isinstance(cls, type) and issubclass(cls, Track) and cls.name == name):
        raise ValueError(f"track {name!r} is {cls!r}, not a Track class named {name!r}; give the "
                         f"class the attribute name = {name!r} (and derive it from Track)")


#: The tracks: the built-in ones in output order (name -> "module:class", imported when used),
#: then those registered in process, then entry points by name.
TRACKS: Registry[type[Track]] = Registry(GROUP, "track", {
    "sins": "navtwin.host.tracks.sins:SinsTrack",
    "wsn": "navtwin.host.tracks.wsn:WsnTrack",
    "kf": "navtwin.host.tracks.kf:KfTrack",
    "ekf": "navtwin.host.tracks.ekf:EkfTrack",
    "ukf": "navtwin.host.tracks.ukf:UkfTrack",
    "lc": "navtwin.host.tracks.lc:LcTrack",
    "tc": "navtwin.host.tracks.tc:TcTrack",
    "fatci": "navtwin.host.tracks.fatci:FatciTrack",
    "centroid": "navtwin.host.tracks.centroid:CentroidTrack",
    "wcl": "navtwin.host.tracks.centroid:WclTrack",
    "geosins": "navtwin.host.tracks.geodetic:GeoSinsTrack",
    "kf-rel": "navtwin.host.tracks.relative:KfRelTrack",
    "hinf": "navtwin.host.tracks.hinf:HinfTrack",
    "hinf+lssvm": "navtwin.host.tracks.bridging:HinfLssvmTrack",
    "hinf+bp": "navtwin.host.tracks.bridging:HinfBpTrack",
}, check=_check)
BUILT_IN = TRACKS.built_in
names, get, unregister = TRACKS.names, TRACKS.get, TRACKS.unregister

__all__ = ["BUILT_IN", "DEFAULT", "EIGHT", "Estimate", "GROUP", "NoSettings", "TRACKS", "Track", "get", "names",
           "register", "unregister"]


def register(cls: type[Track]) -> type[Track]:
    """Add track class *cls* under ``cls.name`` (usable as a class decorator)."""
    name = getattr(cls, "name", None)
    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"track {cls!r} needs a name: a class attribute like name = \"mine\"")
    return TRACKS.register(name, cls)
