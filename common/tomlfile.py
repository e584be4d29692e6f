"""Reading a TOML file: its document, or ONE line naming the file, where and what is wrong.

Scenarios, host configs and calibration files are read here, so each reports a file it cannot
use alike: ``<file>: <problem>; <fix>``, the line and column of a syntax error included (as
tomllib gives them), and tomllib's limits (an integer of more digits than Python converts,
nesting deeper than the recursion limit) reported rather than raised.
"""
from __future__ import annotations

import os
import tomllib
from pathlib import Path

from navtwin.common.limits import limit_problem


def read(path: str | os.PathLike, error: type[Exception] = ValueError,
         name: str | None = None) -> dict:
    """The TOML document at *path*; *error* (one line, the file called *name*, by default its
    path) if it cannot be read or parsed."""
    name = str(path) if name is None else name
    try:
        text = Path(path).read_text(encoding="utf-8")  # TOML is UTF-8, whatever the locale says
    except OSError as e:
        raise error(f"{name}: cannot read ({e.strerror}); check the path") from None
    except UnicodeDecodeError as e:
        raise error(f"{name}: not UTF-8 text ({e.reason} at byte {e.start}); save it as UTF-8") \
            from None
    return parse(text, name, error)


def parse(text: str, name: str, error: type[Exception] = ValueError) -> dict:
    """The TOML document *text* of the file called *name*; *error* (one line) if it is not one."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:  # its text names the line and column
        raise error(f"{name}: not valid TOML ({e}); fix the syntax") from None
    except (ValueError, RecursionError) as e:  # tomllib's limits: an integer's digits, nesting
        raise error(f"{name}: {limit_problem(e)}; shorten it") from None
