"""The shipped scenarios: their directory and names, read without importing the scenario
module (the command line lists them in its help at every start)."""
from __future__ import annotations

from pathlib import Path

DIR = Path(__file__).resolve().parent / "scenarios"
NAMES = tuple(sorted(p.stem for p in DIR.glob("*.toml")))
