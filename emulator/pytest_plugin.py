"""pytest plugin: fixtures that start an emulated lab (registered via pytest11 as ``navtwin``).

Fixtures:

``navtwin_lab``
    a factory: ``lab = navtwin_lab("office", seed=3, duration=20)`` starts ``navtwin emulate``
    (see :func:`navtwin.emulator.api.emulate` for the keywords) and returns the running
    :class:`navtwin.emulator.api.Lab`; every lab the test started is stopped at teardown.
``navtwin_office``, ``navtwin_corridor``, ``navtwin_corridor_outage``
    one running lab of that shipped scenario with the command-line defaults.

Options: ``--navtwin-speed realtime|max|FACTOR`` (default realtime) and ``--navtwin-seed N``
(default: the scenario's) are the defaults of every lab the fixtures start.

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

from contextlib import ExitStack

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


@pytest.fixture
def navtwin_lab(request):
    """Factory fixture: ``navtwin_lab(scenario="office", **emulate_keywords) -> Lab``."""
    with ExitStack() as stack:
        def start(scenario: str = "office", **kw):
            kw.setdefault("speed", request.config.getoption("navtwin_speed"))
            kw.setdefault("seed", request.config.getoption("navtwin_seed"))
            return stack.enter_context(emulate(scenario, **kw))

        yield start


def _scenario_fixture(name: str):
    def lab(navtwin_lab):
        return navtwin_lab(name)

    lab.__doc__ = f"A running lab of the shipped scenario {name!r}."
    return pytest.fixture(name=f"navtwin_{name.replace('-', '_')}")(lab)


for _name in SCENARIO_NAMES:
    globals()[f"navtwin_{_name.replace('-', '_')}"] = _scenario_fixture(_name)
