"""Fusion tracks, one module each, registered by name (docs/filters.md).

Built in, in output order: ``sins``, ``wsn``, ``kf``, ``ekf``, ``ukf`` (000's) and ``lc``,
``tc``, ``fatci`` (001's). A track of a user's
package is added with :func:`register` (in process), or by an entry point in the group
``navtwin.tracks`` whose name is the track's name and whose object is its class::

    [project.entry-points."navtwin.tracks"]
    mine = "mypkg.tracks:MyTrack"

Registered tracks follow the built-in ones in output order, in the order they were added
(entry points by name). ``--filters all`` and ``[filters] enabled`` accept every name.
"""
from __future__ import annotations

import importlib

from navtwin.protocols.plugins import entry_points

from .base import Estimate, NoSettings, Track

#: The built-in tracks in output order: name -> "module:class" (imported when used).
_BUILT_IN = {
    "sins": "navtwin.host.tracks.sins:SinsTrack",
    "wsn": "navtwin.host.tracks.wsn:WsnTrack",
    "kf": "navtwin.host.tracks.kf:KfTrack",
    "ekf": "navtwin.host.tracks.ekf:EkfTrack",
    "ukf": "navtwin.host.tracks.ukf:UkfTrack",
    "lc": "navtwin.host.tracks.lc:LcTrack",
    "tc": "navtwin.host.tracks.tc:TcTrack",
    "fatci": "navtwin.host.tracks.fatci:FatciTrack",
}
BUILT_IN = tuple(_BUILT_IN)
#: What runs when no filters are named: 000's tracks. 001's error-state tracks (lc, ...) run
#: when named (``--filters``, ``[filters] enabled``): together they add about 0.6 of the
#: five's replay time (docs/lab.md, "Replay with all eight tracks").
DEFAULT = ("sins", "wsn", "kf", "ekf", "ukf")
GROUP = "navtwin.tracks"
_registered: dict[str, type[Track]] = {}

__all__ = ["BUILT_IN", "DEFAULT", "Estimate", "GROUP", "NoSettings", "Track", "get", "names", "register",
           "unregister"]


def register(cls: type[Track]) -> type[Track]:
    """Add track class *cls* under ``cls.name`` (usable as a class decorator)."""
    name = getattr(cls, "name", None)
    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"track {cls!r} needs a name: a class attribute like name = \"mine\"")
    if name in BUILT_IN or name in _registered:
        raise ValueError(f"track {name!r} is already registered; choose another name")
    _registered[name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove a track added with :func:`register`."""
    del _registered[name]


def _entry_points() -> dict:
    return {ep.name: ep for ep in entry_points(GROUP)
            if ep.name not in BUILT_IN and ep.name not in _registered}


def names() -> tuple[str, ...]:
    """Every track name in output order: built in, registered, then entry points."""
    return (*BUILT_IN, *_registered, *_entry_points())


def get(name: str) -> type[Track]:
    """The track class registered as *name*; KeyError if there is none."""
    if name in _BUILT_IN:
        module, cls = _BUILT_IN[name].split(":")
        return getattr(importlib.import_module(module), cls)
    if name in _registered:
        return _registered[name]
    ep = _entry_points().get(name)
    if ep is None:
        raise KeyError(name)
    cls = ep.load()
    if not (isinstance(cls, type) and issubclass(cls, Track) and cls.name == name):
        raise ValueError(f"entry point {name} = {ep.value!r} in {GROUP} is not a Track class "
                         f"named {name!r}; fix the package that declares it")
    return cls
