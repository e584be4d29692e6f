"""navtwin bench emulator-writes: a short run on real PTYs (no timed assertion: the figures are
whatever the machine gives)."""
from __future__ import annotations

import pytest

from navtwin.emulator.bench_writes import writes


@pytest.mark.pty
def test_a_short_run_times_the_loops_writes_beside_os_write():
    out = writes([2], 3.0, 1)
    (row,) = out["rows"]
    # 2 cars' 3 s: 600 SINS frames, about as many 0x90 frames, 240 nanoLOC reports
    assert row["ports"] == 6 and row["writes"] > 1000 and row["mean_chunk_bytes"] > 0
    assert 0 < row["write_us"] < row["loop_us_per_write"]
    assert row["ours_us_per_write"] == row["loop_us_per_write"] - row["write_us"]
