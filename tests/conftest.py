"""The tests' shared fixtures (their shared functions and constants: tests/helpers.py).
Fixture files live in fixtures/ at the project root."""
from pathlib import Path

import pytest

from .helpers import ROOT


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture
def small_fs(tmp_path):
    """A 1 MiB tmpfs, to fill up (write failures with ENOSPC); skipped where mount fails."""
    import subprocess

    d = tmp_path / "small"
    d.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(d)],
                      capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root or a user namespace)")
    yield d
    subprocess.run(["umount", str(d)], check=True)
