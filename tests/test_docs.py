"""The docs a new user follows stay true: every ``navtwin`` command in the fenced blocks of
README.md and docs/tutorial.md parses with today's command line, and the tutorial's examples
(docs/examples/) run against the emulated lab."""
from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from navtwin.cli.main import build_parser

from .helpers import NAVTWIN, ROOT

DOCS = ("README.md", "docs/tutorial.md")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)
NOT_SHELL = {"python", "toml", "json", "text"}  # text: output only
SEPARATORS = {"|", "||", "&", "&&", ";", "(", ")"}


def shell_lines(text: str):
    """Command lines of the shell blocks: the ``$ `` lines of a block that has prompts (the
    rest is output), else every line; continuation lines joined."""
    for lang, body in FENCE.findall(text):
        if lang in NOT_SHELL:
            continue
        lines = body.replace("\\\n", " ").splitlines()
        if any(line.startswith("$ ") for line in lines):
            lines = [line[2:] for line in lines if line.startswith("$ ")]
        yield from lines


def simple_commands(line: str):
    """The argv of each simple command in a shell line, without redirections and comments
    (a small subset of sh: what the docs use)."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    argv, tokens = [], list(lexer)
    while tokens:
        token = tokens.pop(0)
        if token in SEPARATORS:
            yield argv
            argv = []
        elif token in (">", ">>", "<"):
            tokens[:1] = []  # the file
            if argv and argv[-1].isdigit():  # 2>file lexes as 2, >, file
                argv.pop()
        else:
            argv.append(token)
    yield argv


def navtwin_commands(doc: str) -> list[list[str]]:
    text = (ROOT / doc).read_text(encoding="utf-8")
    return [argv[1:] for line in shell_lines(text) for argv in simple_commands(line)
            if argv[:1] == ["navtwin"]]


@pytest.mark.parametrize("doc", DOCS)
def test_every_navtwin_command_in_the_docs_parses(doc, capsys):
    commands = navtwin_commands(doc)
    assert commands, f"no navtwin command found in {doc}"
    parser = build_parser()
    for argv in commands:
        try:
            args = parser.parse_args(argv)
        except SystemExit:
            pytest.fail(f"{doc}: 'navtwin {shlex.join(argv)}' does not parse: "
                        f"{capsys.readouterr().err.strip()}")
        assert args.command, f"{doc}: 'navtwin {shlex.join(argv)}' names no subcommand"


def test_the_docs_check_sees_every_form_the_docs_use():
    line = "navtwin ctl unplug xbee; navtwin ctl replug xbee  # pull the cable"
    assert [a for a in simple_commands(line)] == [["navtwin", "ctl", "unplug", "xbee"],
                                                  ["navtwin", "ctl", "replug", "xbee"]]
    assert list(simple_commands("navtwin host --xbee X 2> host.err > out.jsonl &")) == \
        [["navtwin", "host", "--xbee", "X"], []]
    block = "```console\n$ navtwin lab \\\n    --duration 5\nnavtwin output: ignored\n```\n"
    assert list(shell_lines(block)) == ["navtwin lab      --duration 5"]


@pytest.mark.pty
def test_the_readme_python_runs_quietly(tmp_path):
    """The README's Python block as a newcomer pastes it: it runs, and unplugging the
    coordinator's cable leaves no open digi-xbee device logging failed reads."""
    pytest.importorskip("digi.xbee")
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = [body for lang, body in FENCE.findall(text) if lang == "python"]
    assert len(blocks) == 1
    p = subprocess.run([sys.executable, "-c", blocks[0]], cwd=tmp_path, capture_output=True,
                       text=True, timeout=180)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout == "Role.COORDINATOR\n"
    assert len(p.stderr.splitlines()) < 5, p.stderr[:3000]


def ci_job(tmp_path, golden_seed: int):
    """docs/examples/ci/lab-tests.sh as the CI job of docs/testing.md runs it, on the
    tutorial's example tests (docs/examples/), with a golden recording of the job's run
    (office, 2 s) made with seed *golden_seed*."""
    golden = tmp_path / "golden"
    made = subprocess.run([*NAVTWIN, "emulate", "--scenario", "office", "--seed",
                           str(golden_seed), "--speed", "max", "--duration", "2", "--record",
                           golden, "--quiet"], capture_output=True, text=True, timeout=120)
    assert made.returncode == 0, made.stderr
    return subprocess.run(["bash", str(ROOT / "docs" / "examples" / "ci" / "lab-tests.sh")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "GOLDEN": str(golden),
                               "TESTS": str(ROOT / "docs" / "examples"),
                               "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"})


@pytest.mark.pty
@pytest.mark.slow
def test_the_ci_job_example_runs_the_tutorial_tests_and_keeps_a_golden(tmp_path):
    """The CI job passes on a golden of the same run, and the tutorial's example tests pass
    in it (pytest with navtwin's plugin, expect and the cassette)."""
    job = ci_job(tmp_path, 1)  # the job's own seed: the same bytes
    assert job.returncode == 0, job.stdout[-3000:] + job.stderr[-2000:]
    assert re.search(r"\b6 passed\b", job.stdout), job.stdout[-2000:]
    assert "sins (sins): equal" in (tmp_path / "lab-artifacts" / "diff.txt").read_text()


def test_the_ci_job_example_fails_on_a_changed_golden_with_the_diff(tmp_path):
    job = ci_job(tmp_path, 2)  # another seed: other bytes
    assert job.returncode == 1, job.stdout[-3000:] + job.stderr[-2000:]
    assert "first divergence" in job.stdout and "record the golden again" in job.stderr
    assert json.loads((tmp_path / "lab-artifacts" / "diff.json").read_text())
    assert "passed" not in job.stdout  # the job stops at the first failing step


@pytest.mark.pty
def test_the_tutorial_xbee_script_reads_the_coordinator():
    pytest.importorskip("digi.xbee")
    from navtwin.emulator.api import emulate

    with emulate("office", duration=60) as lab:
        p = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "xbee_coordinator.py"),
                            lab.ports["xbee"]], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-3000:]
    lines = p.stdout.splitlines()
    assert lines[0] == "role Role.COORDINATOR address 0013A20040A1B2C3 node LAB-COORD"
    assert "VR 21a7" in lines and "AP 02" in lines
    assert "0x90 from 0013A20040A1B2D4 30 bytes" in lines
    first, last = map(int, re.fullmatch(r"100 SINS frames, seq (\d+) to (\d+)", lines[-1]).groups())
    assert (last - first) % 65536 == 99  # consecutive: no sample lost


@pytest.mark.parametrize("path", sorted((ROOT / "docs" / "examples").glob("*.toml")), ids=lambda p: p.name)
def test_every_example_scenario_loads_and_names_its_base(path):
    """The example scenarios docs/results.md and the tutorial sweep: each loads, and changes
    some setting of the shipped scenario it extends (not only its name)."""
    from navtwin.emulator.scenario import load_scenario

    def settings(sc):
        return [line for line in sc.to_toml().splitlines() if not line.startswith(("name", "description"))]

    base = load_scenario(re.search(r'^base = "([^"]+)"', path.read_text(), re.M).group(1))
    assert settings(load_scenario(path)) != settings(base)
