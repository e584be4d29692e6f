"""pytest plugin: fixtures that start an emulated lab (registered via pytest11 as ``navtwin``).

Fixtures:

``navtwin_lab``
    a factory: ``lab = navtwin_lab("office", seed=3, duration=20)`` starts ``navtwin emulate``
    (see :func:`navtwin.emulator.api.emulate` for the keywords) and returns the running
    :class:`navtwin.emulator.api.Lab`; every lab the test started is stopped at teardown.
``navtwin_office``, ``navtwin_corridor``, ``navtwin_corridor_outage``
    one running lab of that shipped scenario with the command-line defaults.

``navtwin_cassette``
    a factory for tests of your own host code that need no lab once recorded:
    ``ports = navtwin_cassette("office", seed=3)`` returns ``{port: PTY path}``. With
    ``pytest --navtwin-record`` it starts the lab (as ``navtwin_lab``) and relays each port
    through a PTY of its own, saving the exchange at teardown as the test's cassette,
    ``cassettes/<test name>/`` beside the test file (emulator.cassette, format there and in
    docs/testing.md). Without the flag it replays that cassette with no emulator process:
    the recorded device bytes in order, each after the writes that preceded it, and fails the
    test with the frame-level diff (protocols.diff) when the host code writes something else.
    A recording run saves the cassette only when the test passed: a failed test keeps the
    cassette it had (a warning says so), so a broken run never becomes the reference.

``navtwin_golden``
    ``navtwin_golden(run)`` compares the recording directory *run* (``emulate(...,
    record=run)``) with the test's golden, the recording ``goldens/<test name>/`` beside the
    test file, frame by frame (protocols.diff), and fails with the diff's text when they
    differ; with ``pytest --navtwin-update-goldens`` it writes *run* as the golden instead.

Options: ``--navtwin-speed realtime|max|FACTOR`` (default realtime) and ``--navtwin-seed N``
(default: the scenario's) are the defaults of every lab the fixtures start;
``--navtwin-record`` records the cassettes instead of replaying them;
``--navtwin-update-goldens`` rewrites the goldens instead of comparing with them.

The labs have the expectations of :class:`navtwin.emulator.api.Lab` (emulator.expect):
``lab.expect(port, match, timeout)`` (bytes, a bytes regex, or a predicate on decoded frames),
``lab.expect_none(port, match, within)`` and ``lab.idle(port, seconds)``, with timeouts in
device time when ``--navtwin-speed`` is ``max`` or a factor, and failures (AssertionErrors)
that show the last frames decoded with their fields.

Example::

    def test_my_host_reads_sins(navtwin_office):
        with serial.Serial(navtwin_office.ports["sins"], 115200, timeout=2) as ser:
            assert ser.read(30)

    def test_the_board_restarts_its_counter(navtwin_office):
        navtwin_office.expect("sins", lambda f: f.seq >= 200, timeout=10)
        navtwin_office.reset("board")
        navtwin_office.expect("sins", lambda f: f.seq < 5, timeout=10)
"""
from __future__ import annotations

import re
import shutil
from contextlib import ExitStack
from pathlib import Path

import pytest

from .api import emulate
from .scenario import SCENARIO_NAMES


def pytest_addoption(parser) -> None:
    group = parser.getgroup("navtwin", "navtwin emulated lab")
    group.addoption("--navtwin-speed", default="realtime", metavar="realtime|max|FACTOR",
                    help="speed of the labs started by the navtwin fixtures (default realtime)")
    group.addoption("--navtwin-seed", type=int, default=None, metavar="N",
                    help="seed of the labs started by the navtwin fixtures "
                         "(default: the scenario's)")
    group.addoption("--navtwin-record", action="store_true", default=False,
                    help="navtwin_cassette: run the lab and record each test's cassette "
                         "(default: replay the cassettes with no lab)")
    group.addoption("--navtwin-update-goldens", action="store_true", default=False,
                    help="navtwin_golden: write each test's run as its golden recording "
                         "(default: compare the run with the golden)")


_OUTCOME = pytest.StashKey[str]()


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    # the call phase's outcome, for the fixtures that act at teardown on how the test went
    report = yield
    if report.when == "call":
        item.stash[_OUTCOME] = report.outcome
    return report


@pytest.fixture
def navtwin_lab(request):
    """Factory fixture: ``navtwin_lab(scenario="office", **emulate_keywords) -> Lab``."""
    with ExitStack() as stack:
        def start(scenario: str = "office", **kw):
            kw.setdefault("speed", request.config.getoption("navtwin_speed"))
            kw.setdefault("seed", request.config.getoption("navtwin_seed"))
            return stack.enter_context(emulate(scenario, **kw))

        yield start


def _test_dir(request, kind: str) -> Path:
    """``<kind>/<test name>/`` beside the test file (parameters made file-name safe)."""
    return request.node.path.parent / kind / re.sub(r"[^\w.-]", "_", request.node.name)


@pytest.fixture
def navtwin_golden(request):
    """``navtwin_golden(run)``: the recording *run* compared with the test's golden, or
    written as it with ``--navtwin-update-goldens``."""
    golden = _test_dir(request, "goldens")

    def check(run) -> None:
        if request.config.getoption("navtwin_update_goldens"):
            shutil.rmtree(golden, ignore_errors=True)
            shutil.copytree(run, golden)
            return
        if not golden.exists():
            pytest.fail(f"no golden at {golden}: write it with 'pytest --navtwin-update-goldens'",
                        pytrace=False)
        from ..protocols.diff import diff_recordings  # here: pytest loads this plugin in
        # every session of an environment with navtwin, most of which never compare

        diff = diff_recordings(golden, run)
        assert diff.equal, (diff.text() + "\nif the change is meant, rewrite the golden with "
                            "'pytest --navtwin-update-goldens'")

    return check


@pytest.fixture
def navtwin_cassette(request, navtwin_lab):
    """Factory fixture: ``navtwin_cassette(scenario="office", **emulate_keywords) -> {port:
    PTY path}``, recorded against the lab with ``--navtwin-record``, else replayed."""
    from .cassette import Player, Recorder  # here, as diff_recordings above
    from .scenario import load_scenario

    directory = _test_dir(request, "cassettes")
    relays = []

    def ports(scenario: str = "office", **kw) -> dict[str, str]:
        if relays:
            raise ValueError("navtwin_cassette: one cassette per test; call it once")
        if request.config.getoption("navtwin_record"):
            relay = Recorder(navtwin_lab(scenario, **kw), load_scenario(scenario))
        else:
            relay = Player(directory)
        relays.append(relay)
        relay.start()
        return dict(relay.ports)

    yield ports
    for relay in relays:
        relay.close()
        if isinstance(relay, Recorder):
            if request.node.stash.get(_OUTCOME, "failed") == "passed":
                relay.save(directory)
            else:
                request.node.warn(pytest.PytestWarning(
                    f"navtwin_cassette: the test did not pass; {directory} keeps the cassette "
                    "it had (fix the test and record again)"))
        else:
            relay.check()


def _scenario_fixture(name: str):
    def lab(navtwin_lab):
        return navtwin_lab(name)

    lab.__doc__ = f"A running lab of the shipped scenario {name!r}."
    return pytest.fixture(name=f"navtwin_{name.replace('-', '_')}")(lab)


for _name in SCENARIO_NAMES:
    globals()[f"navtwin_{_name.replace('-', '_')}"] = _scenario_fixture(_name)
