"""The layers' import rules, read from every module's imports with ``ast`` (lazy imports inside
functions included): a package imports only the layers below it, nothing but the command line
imports the command line, and the command line (argument parsing) lives in ``cli`` alone.
Ports declare themselves: no port's name decides anything outside the declarations.

An import is counted by the package it lands in, however it is written: ``protocols.x``,
``navtwin.protocols.x`` (the installed namespace) and a relative import that resolves there
are the same package.
"""
from __future__ import annotations

import ast
import fnmatch
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NAMESPACE = "navtwin"

#: Which of our packages each package may import (besides itself). cli may import anything;
#: every package of ours must be listed, so a new one needs a decision here.
ALLOWED = {
    "protocols": set(),
    "common": {"protocols"},
    "emulator": {"protocols", "common"},
    "host": {"protocols", "common"},
    "lab": {"protocols", "common", "emulator", "host"},
    "cli": {"protocols", "common", "emulator", "host", "lab"},
    # the namespace itself: its version, and ``python -m navtwin`` (navtwin/__main__.py)
    "navtwin": {"protocols", "cli"},
}
#: ``python -m navtwin`` is the command line's entry: the one module outside cli that runs it.
CLI_ENTRY = ROOT / "navtwin" / "__main__.py"


def packages(root: Path = ROOT) -> list[str]:
    """Our top-level packages: the repository's folders with an ``__init__.py``, tests aside."""
    return sorted(p.parent.name for p in root.glob("*/__init__.py") if p.parent.name != "tests")


def imported_packages(source: str, module: str, ours: set[str]) -> list[tuple[int, str]]:
    """``(line, package)`` for each import in *source* (the text of dotted *module*, e.g.
    ``emulator.lab`` or ``emulator``'s ``__init__`` as ``emulator.__init__``) that lands in
    one of *ours*; an import of the bare namespace counts as ``navtwin``."""
    package = module.split(".")[:-1]  # the package a relative import starts from
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                up = len(package) - (node.level - 1)
                base = package[:up] if up > 0 else []  # above the top: the sibling packages
                parts = base + (node.module.split(".") if node.module else [])
                # "from . import x" / "from .. import host": the names may be the packages
                targets = [".".join(parts)] if parts else [a.name for a in node.names]
            else:
                targets = [node.module]
        else:
            continue
        for target in targets:
            parts = target.split(".")
            if parts[0] == NAMESPACE:
                parts = parts[1:] or [NAMESPACE]
            if parts[0] in ours or parts[0] == NAMESPACE:
                found.append((node.lineno, parts[0]))
    return found


def modules(package: str):
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        yield path, ".".join(rel.parts)


def violations(package: str) -> list[str]:
    ours = set(packages())
    allowed = ALLOWED[package] | {package}
    return [f"{path.relative_to(ROOT)}:{line} imports {target}"
            for path, module in modules(package)
            for line, target in imported_packages(path.read_text(), module, ours)
            if target not in allowed]


def test_every_package_has_a_layer():
    assert set(packages()) <= set(ALLOWED), "add the new package to ALLOWED (and docs)"


@pytest.mark.parametrize("package", packages())
def test_imports_follow_the_layers(package):
    assert violations(package) == [], f"{package} may import only {sorted(ALLOWED[package])}"


def test_nothing_but_cli_imports_cli():
    ours = set(packages())
    found = [f"{path.relative_to(ROOT)}:{line}" for package in ours - {"cli"}
             for path, module in modules(package) if path != CLI_ENTRY
             for line, target in imported_packages(path.read_text(), module, ours)
             if target == "cli"]
    assert found == []


def test_argument_parsing_lives_in_cli():
    """A main or a subcommand's parser outside cli is a command line in a library layer."""
    found = [f"{path.relative_to(ROOT)}:{node.lineno}" for package in set(packages()) - {"cli"}
             for path, _ in modules(package)
             for node in ast.walk(ast.parse(path.read_text()))
             if isinstance(node, (ast.Import, ast.ImportFrom))
             and "argparse" in ([a.name for a in node.names] if isinstance(node, ast.Import)
                                else [node.module])]
    assert found == [], "move the command line into cli/"


@pytest.mark.parametrize("source, module, expected", [
    ("import protocols.xbee", "host.pipeline", ["protocols"]),
    ("from navtwin.host import config", "emulator.x", ["host"]),
    ("import navtwin.cli.main as m", "lab.x", ["cli"]),
    ("import navtwin", "protocols.x", ["navtwin"]),
    ("from . import stream", "protocols.decode", ["protocols"]),
    ("from .runner import wire_ns", "emulator.__init__", ["emulator"]),
    ("from ..sins import x", "host.filters.kf", ["host"]),
    ("from ..host import config", "emulator.world", ["host"]),  # once under navtwin/
    ("from .. import cli", "lab.run", ["cli"]),
    ("def f():\n    from cli.main import UsageError", "host.x", ["cli"]),
    ("import numpy, serial\nfrom pathlib import Path", "host.x", []),
])
def test_imports_are_resolved_however_written(source, module, expected):
    ours = {"protocols", "common", "emulator", "host", "lab", "cli"}
    assert [p for _, p in imported_packages(source, module, ours)] == expected


def test_the_build_maps_every_package_folder_into_the_namespace():
    """pyproject's package-dir and packages cover every folder Python imports (one with an
    __init__.py, or a data folder such as emulator/scenarios, which setuptools warns about
    when it is not declared), and package-data every data file in them."""
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folder_of = {name: folder for name, folder in tool["package-dir"].items()}
    want, data = set(), {}
    for name, folder in folder_of.items():
        for d in (ROOT / folder, *(ROOT / folder).rglob("*")):
            files = [f for f in d.iterdir() if f.is_file()] if d.is_dir() else []
            if d.name != "__pycache__" and files:
                package = ".".join((name, *d.relative_to(ROOT / folder).parts))
                want.add(package)
                data[package] = [f.name for f in files if f.suffix != ".py"]
    assert set(tool["packages"]) == want
    assert set(folder_of) == {NAMESPACE, *(f"{NAMESPACE}.{p}" for p in packages() if p != NAMESPACE)}
    for package, names in data.items():
        globs = tool.get("package-data", {}).get(package, ())
        for f in names:
            assert any(fnmatch.fnmatch(f, g) for g in globs), f"{package}: {f} not in package-data"


def test_a_user_package_named_host_imports_beside_navtwin(tmp_path):
    """A lab's own code called host (or protocols, lab, cli) does not collide with navtwin."""
    for name in ("host", "protocols", "lab", "cli"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(f"WHO = 'user {name}'\n")
    code = ("import cli, host, lab, protocols\n"
            "import navtwin.host.config, navtwin.protocols.xbee, navtwin.lab.evaluate, navtwin.cli.main\n"
            "assert [m.WHO for m in (host, protocols, lab, cli)] == "
            "['user host', 'user protocols', 'user lab', 'user cli']\n"
            "assert navtwin.host.config.load('office').anchors\n"
            "print(navtwin.host.config.__name__)")
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "navtwin.host.config"


#: the lab's ports, and the modules that declare them, their formats and their devices: the
#: only places a port's name may decide something (protocols.ports)
PORT_NAMES = {"sins", "xbee", "nanoloc"}
DECLARATIONS = {ROOT / "protocols" / "ports.py", ROOT / "protocols" / "formats.py",
                ROOT / "emulator" / "devices.py"}


def _port_literals(node):
    if isinstance(node, ast.Constant) and node.value in PORT_NAMES:
        yield node.value
    elif isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        for element in node.elts:
            yield from _port_literals(element)


def port_name_decisions(source: str) -> list[tuple[int, str]]:
    """``(line, port)`` for each comparison (``==``, ``in``, ...) or ``case`` against a port's
    name in a decision: the test of an if/elif, while, ternary or comprehension, or a match."""
    tests = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.If, ast.While, ast.IfExp)):
            tests.append(node.test)
        elif isinstance(node, ast.comprehension):
            tests += node.ifs
        elif isinstance(node, ast.Match):
            tests += [case.pattern for case in node.cases]
    found = []
    for test in tests:
        for node in ast.walk(test):
            if isinstance(node, ast.Compare):
                found += [(node.lineno, name) for operand in (node.left, *node.comparators)
                          for name in _port_literals(operand)]
            elif isinstance(node, ast.MatchValue):
                found += [(node.lineno, name) for name in _port_literals(node.value)]
    return sorted(found)


@pytest.mark.parametrize("source, expected", [
    ('if port == "xbee":\n    pass', [(1, "xbee")]),
    ('x = a if "sins" in inputs else b', [(1, "sins")]),
    ('if p in ("xbee", "sins"):\n    pass', [(1, "sins"), (1, "xbee")]),
    ('while name != "nanoloc":\n    pass', [(1, "nanoloc")]),
    ('y = [p for p in ps if p == "xbee"]', [(1, "xbee")]),
    ('match port:\n    case "sins":\n        pass', [(2, "sins")]),
    ('lines["xbee"].put(t, x)\nif kind == "sins_track":\n    pass', []),
])
def test_port_name_decisions_are_found_however_written(source, expected):
    assert port_name_decisions(source) == expected


def test_no_port_name_decides_outside_the_port_declarations():
    """A port's behaviour is read from its declaration (protocols.ports: its format, decoder,
    device, whether the host reads or writes it), so adding a port is a declaration and a
    device model, never another branch (docs/architecture.md, "A port")."""
    found = [f"{path.relative_to(ROOT)}:{line} decides on {name!r}"
             for package in packages() for path, _ in modules(package) if path not in DECLARATIONS
             for line, name in port_name_decisions(path.read_text())]
    assert found == [], "read it from the port's declaration (protocols.ports) instead"


def module_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Each of our modules (dotted, a package by its own name) -> the modules of ours it
    imports, at the top or inside a function alike; ``from pkg import name`` counts as
    pkg.name when that is a module, else as pkg. An import under ``if TYPE_CHECKING:`` never
    runs and is left out."""
    paths = {}
    for package in packages(root):
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path

    def ours(target: str) -> str | None:
        parts = target.split(".")
        parts = parts[1:] if parts[0] == NAMESPACE else parts
        while parts and ".".join(parts) not in paths:
            parts = parts[:-1]
        return ".".join(parts) or None

    graph = {}
    for module, path in paths.items():
        tree = ast.parse(path.read_text())
        typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                       and "TYPE_CHECKING" in ast.unparse(node.test)
                       for stmt in node.body for n in ast.walk(stmt)}
        here = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        found = set()
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = ".".join((here[:len(here) - node.level + 1] if node.level else [])
                                + (node.module.split(".") if node.module else []))
                targets = [f"{base}.{a.name}" for a in node.names]  # ours() drops a non-module
            else:
                continue
            found |= {m for t in targets if (m := ours(t)) and m != module}
        graph[module] = found
    return graph


def import_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One cycle of *graph* as the modules along it (the first one repeated at the end), or []."""
    state: dict[str, int] = {}  # 1: on the path being walked, 2: done, no cycle through it
    path: list[str] = []

    def walk(module: str) -> list[str]:
        state[module] = 1
        path.append(module)
        for nxt in sorted(graph.get(module, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := walk(nxt)):
                return cycle
        state[module] = 2
        path.pop()
        return []

    for module in sorted(graph):
        if module not in state and (cycle := walk(module)):
            return cycle
    return []


def test_no_import_cycle_among_our_modules():
    """Two modules that import each other (even inside a function) depend on their import
    order and cannot be understood, tested or split apart alone: the shared part belongs in a
    third module both import (as host.settings is for host.config and host.estimator)."""
    cycle = import_cycle(module_graph())
    assert cycle == [], "import cycle: " + " -> ".join(cycle)


@pytest.mark.parametrize("files, cycle", [
    ({"host/a.py": "from . import b", "host/b.py": "def f():\n    from .a import x"},
     ["host.a", "host.b", "host.a"]),
    ({"host/a.py": "from navtwin.host.b import y", "host/b.py": "import navtwin.host.a"},
     ["host.a", "host.b", "host.a"]),
    ({"host/a.py": "from . import b", "host/b.py": "if TYPE_CHECKING:\n    from .a import x"}, []),
    ({"host/a.py": "from .b import y", "host/b.py": "import numpy"}, []),
])
def test_import_cycles_are_found_however_written(tmp_path, files, cycle):
    for name, text in {"host/__init__.py": "", **files}.items():
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text(text)
    assert import_cycle(module_graph(tmp_path)) == cycle
