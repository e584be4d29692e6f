"""``navtwin bench NAME --setting value``: a benchmark's settings declared once (a table class
of schema keys), listed by ``NAME --help``, checked as a table is, a bad one one line with exit
status 2 (issue 18 item 6)."""
from __future__ import annotations

import pytest

from navtwin.cli.bench import available, settings
from navtwin.cli.main import UsageError, main
from navtwin.lab.bench import Replay, Soak


def run(capsys, *argv):
    try:
        code = main(["bench", *argv])
    except SystemExit as e:  # argparse
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err.strip()


def test_settings_are_parsed_into_the_benchmarks_table():
    s = settings("lab-soak", Soak, {"seconds": "3600", "faults": True, "dir": "/tmp/soak"})
    assert s == Soak(seconds=3600.0, faults=True, dir="/tmp/soak")
    assert settings("lab-soak", Soak, {}) == Soak()  # none given: the defaults (smaller with --quick)
    assert settings("host-replay", Replay, {"recording": "rec", "filters": "wsn", "runs": "2"}) == \
        Replay(recording="rec", filters="wsn", runs=2)


@pytest.mark.parametrize("argv, line", [
    (["lab-soak", "--seconds", "5"], "--seconds must be in [30, 36000] (got 5 s); use a value "
                                     "from 30 to 36000"),
    (["lab-soak", "--seconds", "an hour"], "--seconds must be a number (got 'an hour')"),
    (["host-filters", "--steps", "1.5"], "--steps must be an integer (got '1.5')"),
    (["host-replay", "--filters", "kf,pf"], "--filters unknown filter 'pf'; use a comma list of"),
    (["lab-sweep", "--seeds", "nan"], "--seeds must be an integer (got 'nan')"),
    (["lab-sweep", "--duration", "inf"], "--duration must be a finite number (got inf)"),
])
def test_a_bad_setting_is_one_line_naming_its_flag(capsys, argv, line):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == "" and len(err.splitlines()) == 1
    assert err.startswith(f"navtwin bench: error: {line}")


def test_a_setting_of_another_benchmark_is_refused(capsys):
    code, out, err = run(capsys, "uart-rx", "--steps", "5")
    assert code == 2 and "unrecognized arguments: --steps 5" in err and len(err.splitlines()) == 1


def test_name_help_lists_its_settings_and_bench_help_says_how(capsys):
    code, out, _ = run(capsys, "lab-soak", "--help")
    assert code == 0 and "settings of lab-soak:" in out
    for option in ("--seconds SECONDS", "--faults", "--dir DIR"):
        assert option in out
    assert "30, 36000" in out
    code, out, _ = run(capsys, "--help")
    assert code == 0 and "navtwin bench NAME --help" in out


def test_every_benchmark_with_settings_declares_them_as_a_table():
    from navtwin.common.schema import build

    declared = {name: fn.Settings for name, fn in available().items() if hasattr(fn, "Settings")}
    assert {"lab-soak", "host-replay", "host-filters", "emulator-jitter"} <= set(declared)
    for cls in declared.values():
        build(cls, {})  # every setting has a default


def test_a_setting_the_benchmark_does_not_take_is_one_line():
    with pytest.raises(UsageError, match=r"^lab-soak takes no --steps; its settings: --seconds, "
                                         r"--faults, --dir$"):
        settings("lab-soak", Soak, {"steps": "5"})
