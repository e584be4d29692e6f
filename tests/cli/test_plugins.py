"""A user's package adds a subcommand and a benchmark through the entry-point groups, with no
edit of navtwin: what ``pip install`` of a package declaring them would give."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

from ..helpers import navtwin
from ..packages import write

PLUGIN = '''
from navtwin.cli.main import UsageError


def register(sub):
    p = sub.add_parser("greet", help="say hello to an anchor")
    p.add_argument("anchor", type=int)
    p.set_defaults(func=run)


def run(args):
    if args.anchor < 1:
        raise UsageError(f"anchor {args.anchor}: anchors are numbered from 1")
    print(f"hello anchor {args.anchor}")
    return 0


def benchmarks():
    def toy(quick=False):
        """user: a benchmark from outside navtwin"""
        return {"quick": quick}

    return {"user-toy": toy}
'''

ENTRY_POINTS = """\
[navtwin.commands]
greet = labext:register

[navtwin.benchmarks]
labext = labext:benchmarks
"""


def with_labext(tmp_path: Path, *argv: str) -> subprocess.CompletedProcess:
    """``navtwin *argv`` with the user package labext installed (in *tmp_path*)."""
    return navtwin(*argv, env=write(tmp_path, "labext", ENTRY_POINTS, {"labext.py": PLUGIN}))


def test_a_user_package_adds_a_subcommand(tmp_path):
    assert "greet" in with_labext(tmp_path, "--help").stdout
    p = with_labext(tmp_path, "greet", "3")
    assert (p.returncode, p.stdout) == (0, "hello anchor 3\n")
    p = with_labext(tmp_path, "greet", "0")
    assert (p.returncode, p.stderr) == (2, "navtwin greet: error: anchor 0: anchors are "
                                            "numbered from 1\n")


def test_a_user_package_adds_a_benchmark(tmp_path):
    p = with_labext(tmp_path, "bench", "--list")
    assert "user-toy\tuser: a benchmark from outside navtwin" in p.stdout.splitlines()
    p = with_labext(tmp_path, "bench", "user-toy", "--quick")
    assert json.loads(p.stdout) == {"bench": "user-toy", "quick": True}
