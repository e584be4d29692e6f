"""Timing modes (emulator.timing): chosen by what the process may do, in force for the run's
loop only, and the lateness histogram's bins."""
import os

import pytest

from navtwin.emulator import timing
from navtwin.emulator.api import emulate
from navtwin.emulator.runner import Emulation, RunError
from navtwin.emulator.scenario import load_scenario

from ..helpers import cli_error, fifo_permitted


@pytest.fixture
def no_fifo(monkeypatch):
    """A process that may not take real-time priority."""
    def refuse(*_):
        raise PermissionError(1, "Operation not permitted")
    monkeypatch.setattr(os, "sched_setscheduler", refuse)


def test_auto_takes_real_time_priority_where_permitted_else_slack():
    assert timing.choose().name == ("fifo" if fifo_permitted() else "slack")


def test_auto_falls_to_slack_where_real_time_is_refused(no_fifo):
    assert timing.choose().name == "slack"
    emu = Emulation(load_scenario("office"), speed=1.0, ports=False)
    assert emu.info()["timing"] == "slack"


def test_a_forced_mode_not_permitted_is_one_line(no_fifo):
    with pytest.raises(RunError, match="^timing: fifo is not permitted.*choose auto$"):
        Emulation(load_scenario("office"), speed=1.0, ports=False, timing="fifo")


def test_cli_forced_mode_not_permitted_exits_2(no_fifo, capsys, tmp_path):
    line = cli_error(capsys, "emulate", "--scenario", "office", "--timing", "fifo",
                     "--link-dir", tmp_path / "l")
    assert "--timing fifo is not permitted" in line and "CAP_SYS_NICE" in line
    assert not (tmp_path / "l").exists()  # refused before any port was made


def test_the_api_passes_the_mode_to_the_emulator():
    with emulate("office", speed=50, duration=1, timing="spin") as lab:
        assert lab.info["timing"] == "spin"
        assert lab.wait_done(timeout=30)["timing"] == "spin"


def test_max_speed_has_no_timing_mode():
    emu = Emulation(load_scenario("office"), speed=None, ports=False, duration_s=0.5)
    assert emu.timing is None and "timing" not in emu.info()
    summary = emu.run()
    assert "timing" not in summary and "late" not in summary["ports"]["sins"]


@pytest.mark.parametrize("name", list(timing.MODES))
def test_mode_is_in_force_on_the_loop_and_undone_after(name):
    if name == "fifo" and not fifo_permitted():
        pytest.skip("this process may not take SCHED_FIFO")
    before = os.sched_getscheduler(0), timing._prctl(timing.PR_GET_TIMERSLACK)
    seen = []
    sink = lambda chunk: seen.append((os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK,
                                      timing._prctl(timing.PR_GET_TIMERSLACK)))
    with Emulation(load_scenario("office"), speed=25.0, ports=False, duration_s=0.5,
                   timing=name, sink=sink) as emu:
        summary = emu.run()
    assert summary["timing"] == name and seen
    policies, slacks = {p for p, _ in seen}, {s for _, s in seen}
    assert policies == {os.SCHED_FIFO if name == "fifo" else before[0]}
    # 1 ns asked; a real-time thread has none at all (Linux 6.7+ reports 0)
    assert slacks == {before[1]} if name == "spin" else slacks <= {0, timing.SLACK_NS}
    assert (os.sched_getscheduler(0), timing._prctl(timing.PR_GET_TIMERSLACK)) == before


def test_lateness_bins_are_log_spaced_and_count_each_write():
    assert timing.BINS == ("<10us", "<30us", "<100us", "<300us", "<1ms", "<3ms", "<10ms",
                           ">=10ms")
    late = timing.Lateness(["sins"])
    for ns in (-5, 0, 9_999, 10_000, 299_999, 1_000_000, 9_999_999, 10_000_000, 10**10):
        late.add("sins", ns)
    assert late.histograms() == {"sins": {"<10us": 3, "<30us": 1, "<100us": 0, "<300us": 1,
                                          "<1ms": 0, "<3ms": 1, "<10ms": 1, ">=10ms": 2}}


@pytest.mark.parametrize("name", list(timing.MODES))
def test_making_events_runs_as_an_ordinary_process_and_the_mode_comes_back(name, tmp_path):
    """The world's blocks of a paced run, made by its maker process (emulator.maker): never
    SCHED_FIFO (it would keep the clients off the core while a block is made); the writes
    are real-time all the while."""
    if name == "fifo" and not fifo_permitted():
        pytest.skip("this process may not take SCHED_FIFO")
    from navtwin.emulator.world import World

    seen, make = tmp_path / "policies", World._make

    def watched(self):  # in the maker process: its policy, to a file
        with open(seen, "a") as f:
            f.write(f"{os.getpid()} {os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK}\n")
        return make(self)

    written = []
    sink = lambda chunk: written.append(os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK)
    World._make = watched
    try:
        with Emulation(load_scenario("office"), speed=25.0, ports=False, duration_s=3,
                       timing=name, sink=sink) as emu:
            emu.run()
    finally:
        World._make = make
    made = [line.split() for line in seen.read_text().splitlines()]
    assert {int(p) for p, _ in made if int(p) != os.getpid()}  # the maker made blocks
    assert {int(policy) for _, policy in made} == {os.SCHED_OTHER}
    assert set(written) == {os.SCHED_FIFO if name == "fifo" else os.SCHED_OTHER}
