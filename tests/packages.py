"""A package installed in a temporary directory, as ``pip install`` of a package declaring
entry points would give it: for the tests of navtwin's registries."""
from __future__ import annotations

import sys


def install(tmp_path, monkeypatch, name: str, entry_points: str, source: str = "") -> None:
    """Module *name* with *source*, and its dist-info declaring *entry_points* (the text of
    entry_points.txt), found on sys.path until the test ends."""
    (tmp_path / f"{name}.py").write_text(source)
    info = tmp_path / f"{name}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(entry_points)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, name, raising=False)  # imported anew; dropped after
