"""Library errors name the problem and the setting (``speed: ...``), never a command-line flag;
the command line says the flag (``--speed ...``) through cli.main.flagged (issue 18 item 7)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from navtwin.cli.main import flag, flagged, main
from navtwin.emulator.runner import RunError, parse_speed
from navtwin.emulator.scenario import ScenarioError, load_scenario, with_faults
from navtwin.host.config import ConfigError, parse_filters

ROOT = Path(__file__).resolve().parent.parent
LIBRARY = ("protocols", "common", "emulator", "host", "lab")


def test_no_library_error_names_a_flag():
    """Every string in a raise of the library layers; a quoted navtwin command line (the fix
    'navtwin replay --salvage', or 'pytest --navtwin-record' for the plugin's fixtures) is a
    command to run, not the flag of a setting."""
    found = []
    for pkg in LIBRARY:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if not (isinstance(node, ast.Raise) and node.exc is not None):
                    continue
                for c in ast.walk(node.exc):
                    if isinstance(c, ast.Constant) and isinstance(c.value, str):
                        text = re.sub(r"'(navtwin|pytest) [^']*'", "", c.value)
                        if re.search(r"(^|\W)--[a-z]", text):
                            found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {c.value!r}")
    assert not found, "\n".join(found)


@pytest.mark.parametrize("call, error, setting", [
    (lambda: parse_speed("fast"), RunError, "speed"),
    (lambda: parse_speed("1e9"), RunError, "speed"),
    (lambda: parse_filters("kf,pf"), ConfigError, "filters"),
    (lambda: with_faults(load_scenario("office"), ["byte_drop:port=gps"]), ScenarioError, "fault"),
])
def test_a_library_error_starts_with_its_setting(call, error, setting):
    with pytest.raises(error) as e:
        call()
    assert str(e.value).startswith(f"{setting}: ") and "--" not in str(e.value)


def test_flagged_turns_a_leading_setting_into_its_flag():
    assert flag("link_dir") == "--link-dir"
    assert flagged("record: /x: not empty; pass another") == "--record /x: not empty; pass another"
    assert flagged("link_dir: /x is in use") == "--link-dir /x is in use"
    for plain in ("office.toml: not valid TOML", "unknown track 'x'; use one of a, b",
                  "[filters] enabled: unknown filter 'x'", "anchor 0: anchors are numbered"):
        assert flagged(plain) == plain


@pytest.mark.parametrize("option, start", [
    (["--duration", "99999"], "--duration 99999 is outside"),
    (["--fault", "byte_drop:port=gps"], "--fault byte_drop:port=gps: "),
])
def test_the_command_line_says_the_flag(capsys, tmp_path, option, start):
    code = main(["emulate", "--scenario", "office", *option, "--quiet",
                 "--link-dir", str(tmp_path / "links")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith(f"navtwin emulate: error: {start}")
    assert len(err.splitlines()) == 1
