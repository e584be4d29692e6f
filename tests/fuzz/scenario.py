"""Fuzz target: the scenario reader (emulator.scenario.load_scenario) on a TOML file whose
text is the input; ``base =`` may name a shipped scenario or the file itself."""
from navtwin.emulator.scenario import SCENARIO_DIR, Scenario, ScenarioError, load_scenario

from .harness import check_reader, fixture

NAME = "fuzz.toml"
SEEDS = [p.read_bytes() for p in sorted(SCENARIO_DIR.glob("*.toml"))] + \
    [fixture("golden", "office", "scenario.toml"), b'base = "office"\nduration_s = 1e400\n',
     b'base = "fuzz.toml"\n',
     b'base = "office"\n[magnetometer]\nenabled = true\nrate_hz = 20.0\nhard_iron_ut = [1.0, 2.0, 3.0]\n'
     b'soft_iron = [[1.02, 0.01, 0.0], [0.01, 0.98, 0.0], [0.0, 0.0, 1.0]]\n',
     # tomllib's limits: nesting past the recursion limit, an integer past 4300 digits
     b"duration_s = " + b"[" * 2000, b'base = "office"\nduration_s = ' + b"1" * 4400]


def check(data: bytes) -> None:
    def verify(scenario, _directory):
        assert isinstance(scenario, Scenario)
    check_reader(lambda d: load_scenario(d / NAME), ScenarioError, {NAME: data}, verify)
