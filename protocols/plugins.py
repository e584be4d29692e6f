"""Registries of named plug-ins, and the entry points of installed packages, read once.

Here, in the bottom layer (it imports nothing of ours), so that every layer can declare and
find plug-ins: the wire formats and ports here, the devices and fault kinds of the emulator,
the host's tracks, the command line's commands and benchmarks.

A :class:`Registry` holds one kind of plug-in (fusion tracks, fault kinds, commands,
benchmarks, ports): the built-in ones, named by ``"module:attribute"`` and imported when first
asked for (start-up imports only what it uses); those added in process with
:meth:`Registry.register` (a test, a notebook); then those of installed packages, found in the
registry's entry-point group, each checked when loaded. Names are listed in that order, built-in
first, entry points by name.

Entry points. importlib.metadata reads every installed package's entry_points.txt whichever
group is asked for (``entry_points(group=...)`` selects after the full read), about 2-4 ms a
time, so one read serves every group of the process. A change of ``sys.path`` (a package added
at run time, as a test does) reads again.
"""
from __future__ import annotations

import functools
import importlib
import sys
from collections.abc import Callable, Iterator, Mapping
from importlib import metadata
from typing import Generic, TypeVar

T = TypeVar("T")


def entry_points(group: str) -> tuple:
    """The entry points of *group* in every installed package, sorted by name."""
    return _by_group(tuple(sys.path)).get(group, ())


@functools.lru_cache(maxsize=1)
def _by_group(path: tuple[str, ...]) -> dict[str, tuple]:
    every = metadata.entry_points()  # one read of every package (selects from it do not read)
    return {group: tuple(sorted(every.select(group=group), key=lambda ep: ep.name))
            for group in every.groups}


def load(target: str):
    """The object that ``"module:attribute"`` (or ``"module"``) names."""
    module, _, attr = target.partition(":")
    obj = importlib.import_module(module)
    for part in filter(None, attr.split(".")):
        obj = getattr(obj, part)
    return obj


class Registry(Generic[T]):
    """Named plug-ins of one kind.

    *group*: the entry-point group (``navtwin.tracks``). *noun*: what one is called in
    messages ("track"). *built_in*: name -> the object or its ``"module:attribute"``.
    *check(name, obj)*: raises *error* (one line naming the problem and the fix) when *obj*
    cannot serve as *name*; run on everything registered or loaded from an entry point.
    """

    def __init__(self, group: str, noun: str, built_in: Mapping[str, T | str] | None = None, *,
                 check: Callable[[str, T], None] | None = None,
                 error: type[Exception] = ValueError) -> None:
        self.group, self.noun, self.error = group, noun, error
        self._built_in = dict(built_in or {})
        self._check = check
        self._registered: dict[str, T] = {}
        self._loaded: dict[str, T] = {}

    @property
    def built_in(self) -> tuple[str, ...]:
        return tuple(self._built_in)

    def register(self, name: str, obj: T) -> T:
        """Add *obj* as *name*; *error* if the name is taken or *obj* fails the check."""
        if not (isinstance(name, str) and name):
            raise self.error(f"{self.noun} {obj!r} needs a name; give it one")
        if name in self._built_in or name in self._registered:
            raise self.error(f"{self.noun} {name!r} is already registered; choose another name")
        if self._check is not None:
            self._check(name, obj)
        self._registered[name] = obj
        return obj

    def unregister(self, name: str) -> None:
        """Remove what :meth:`register` added as *name* (KeyError if it did not)."""
        del self._registered[name]

    def _entry_points(self) -> dict:
        return {ep.name: ep for ep in entry_points(self.group)
                if ep.name not in self._built_in and ep.name not in self._registered}

    def names(self) -> tuple[str, ...]:
        """Every name: built in, registered in process, then entry points by name."""
        return (*self._built_in, *self._registered, *self._entry_points())

    def __contains__(self, name: object) -> bool:
        return name in self._built_in or name in self._registered or name in self._entry_points()

    def get(self, name: str) -> T:
        """The plug-in *name*; KeyError if there is none, *error* if its entry point names
        something that fails the check."""
        if name in self._registered:
            return self._registered[name]
        if name in self._loaded:
            return self._loaded[name]
        if name in self._built_in:
            obj = self._built_in[name]
            obj = load(obj) if isinstance(obj, str) else obj
        else:
            ep = self._entry_points().get(name)
            if ep is None:
                raise KeyError(name)
            try:
                obj = ep.load()
            except (ImportError, AttributeError) as e:
                raise self.error(f"entry point {name} = {ep.value!r} in {self.group} does not "
                                 f"load ({e}); fix or uninstall the package that declares it") \
                    from None
            if self._check is not None:
                self._check(name, obj)
        self._loaded[name] = obj  # an entry point's object stays what it was when first asked
        return obj

    def items(self) -> Iterator[tuple[str, T]]:
        """(name, plug-in) of every name, loading each."""
        return ((name, self.get(name)) for name in self.names())

    def unknown(self, names) -> str | None:
        """One line naming the first of *names* that is not registered, and the known ones;
        None when all are."""
        bad = [n for n in names if n not in self]
        if not bad:
            return None
        return f"unknown {self.noun} {bad[0]!r}; use one of {', '.join(self.names())}"
