"""Which navtwin made a result: the version a sweep's cells and a run's report carry.

``0.1.0+<git describe>`` for a checkout, ``-dirty`` appended when a .py or .toml file differs
from its commit (edited docs do not change a result); the package version alone when navtwin
is not run from a git checkout (an installed wheel) or git is not there.
"""
from __future__ import annotations

import subprocess
from pathlib import Path

from navtwin.protocols import __version__


def code_version() -> str:
    """navtwin's version, plus ``git describe`` of its checkout when there is one, with
    ``-dirty`` when a .py or .toml file differs from it."""
    root = str(Path(__file__).resolve().parent.parent)
    try:
        head = subprocess.run(["git", "-C", root, "describe", "--always"], capture_output=True,
                              text=True, timeout=10)
        diff = subprocess.run(["git", "-C", root, "diff", "--quiet", "HEAD", "--", "*.py",
                               "*.toml"], capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return __version__
    if head.returncode != 0:
        return __version__
    return f"{__version__}+{head.stdout.strip()}" + ("-dirty" if diff.returncode else "")
