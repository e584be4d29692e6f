"""The one line that names a missing optional dependency and the extra that installs it
(pyproject.toml's optional-dependencies), for the command line and for a library module
that imports an extra's package only when it is used (host.filters.hinf: cvxpy)."""
from __future__ import annotations

import importlib
from types import ModuleType


def install_line(name: str, extra: str, who: str | None = None) -> str:
    """``[who ]needs NAME, which is not installed; pip install 'navtwin[EXTRA]'``."""
    return f"{who + ' ' if who else ''}needs {name}, which is not installed; pip install 'navtwin[{extra}]'"


class MissingExtra(ModuleNotFoundError):
    """An extra's package is not installed: the message is the line that says which extra
    installs it (the command line prints it as it is, exit status 2)."""


def require(module: str, extra: str, who: str) -> ModuleType:
    """Import *module* of the *extra*; MissingExtra naming *who* needs it when it (or a
    package it imports) is not installed."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        name = (e.name or module).partition(".")[0]
        raise MissingExtra(install_line(name, extra, who), name=name) from None
