"""Tracks, fault kinds, commands and benchmark sets: four registries found one way (issue 18
item 5): navtwin's own declared in code, then the entry points of installed packages, each
checked when loaded; an unknown name is one line listing the known ones."""
import textwrap

import pytest

from navtwin.cli.bench import SETS
from navtwin.cli.main import COMMANDS
from navtwin.emulator.faults import KINDS
from navtwin.host.tracks import TRACKS

from .packages import install

REGISTRIES = {"track": TRACKS, "fault kind": KINDS, "command": COMMANDS, "benchmark set": SETS}

PLUGIN = textwrap.dedent('''
    from dataclasses import dataclass
    from navtwin.emulator.faults import LineFault
    from navtwin.host.tracks import Track

    class Mine(Track):
        name = "reg_mine"

    @dataclass(frozen=True, kw_only=True)
    class Hangup(LineFault):
        KIND = "reg_mine"
        def wrapper(self, rng):
            raise NotImplementedError

    def register(sub):
        sub.add_parser("reg_mine")

    def benchmarks():
        return {}
''')


@pytest.fixture
def package(tmp_path, monkeypatch):
    """An installed package declaring 'reg_mine' in each group."""
    install(tmp_path, monkeypatch, "regmine",
            "[navtwin.tracks]\nreg_mine = regmine:Mine\n[navtwin.faults]\nreg_mine = regmine:Hangup\n"
            "[navtwin.commands]\nreg_mine = regmine:register\n"
            "[navtwin.benchmarks]\nreg_mine = regmine:benchmarks\n", PLUGIN)


@pytest.mark.parametrize("noun", REGISTRIES)
def test_built_in_ones_are_declared_in_code_and_load(noun):
    reg = REGISTRIES[noun]
    assert reg.noun == noun and reg.built_in and reg.names()[:len(reg.built_in)] == reg.built_in
    for name in reg.built_in:
        assert reg.get(name) is not None


@pytest.mark.parametrize("noun", REGISTRIES)
def test_an_entry_point_follows_the_built_in_ones(noun, package):
    reg = REGISTRIES[noun]
    assert reg.names() == (*reg.built_in, "reg_mine")
    assert reg.get("reg_mine").__module__ == "regmine"


@pytest.mark.parametrize("noun", REGISTRIES)
def test_an_unknown_name_is_one_line_listing_the_known(noun):
    reg = REGISTRIES[noun]
    line = reg.unknown([reg.built_in[0], "no_such_one"])
    assert line == f"unknown {noun} 'no_such_one'; use one of {', '.join(reg.names())}"
    assert "\n" not in line and reg.unknown(reg.built_in) is None


def test_an_entry_point_that_is_not_what_its_group_takes_is_refused(tmp_path, monkeypatch):
    install(tmp_path, monkeypatch, "regbad", "[navtwin.tracks]\nreg_bad = regbad:NotATrack\n"
            "[navtwin.faults]\nreg_bad = regbad:NotATrack\n", "class NotATrack:\n    name = 'reg_bad'\n")
    with pytest.raises(ValueError, match="^track 'reg_bad' is .*not a Track class named"):
        TRACKS.get("reg_bad")
    with pytest.raises(ValueError, match="not a DeviceFault or LineFault subclass"):
        KINDS.get("reg_bad")
