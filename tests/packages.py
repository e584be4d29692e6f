"""A package installed in a temporary directory, as ``pip install`` of a package declaring
entry points would give it: for the tests of navtwin's registries and of outside packages
(a track, a fault kind, a port, a command, a benchmark), written once."""
from __future__ import annotations

import os
import sys
import textwrap
from collections.abc import Mapping
from pathlib import Path


def write(root: Path, name: str, entry_points: str,
          files: Mapping[str, str] | None = None) -> dict:
    """Package *name* in *root*: its dist-info declaring *entry_points* (the text of
    entry_points.txt) and *files* (path below *root* -> source, dedented); the environment of
    a process that has it installed (*root* on PYTHONPATH)."""
    info = root / f"{name}-1.0.dist-info"
    info.mkdir(parents=True, exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(entry_points)
    for path, text in (files or {}).items():
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        (root / path).write_text(textwrap.dedent(text))
    path = os.pathsep.join(p for p in (os.environ.get("PYTHONPATH"), str(root)) if p)
    return {**os.environ, "PYTHONPATH": path}


def install(tmp_path, monkeypatch, name: str, entry_points: str, source: str | None = "") -> None:
    """Module *name* with *source* (None: no module, an entry point that cannot load) and its
    dist-info, found on sys.path of this process until the test ends."""
    write(tmp_path, name, entry_points, None if source is None else {f"{name}.py": source})
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, name, raising=False)  # imported anew; dropped after
