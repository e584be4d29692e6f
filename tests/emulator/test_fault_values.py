"""Fault settings are checked against what the code does with them: any value that passes
validation runs (the extremes of every kind's ranges, the finest schedules), and a fault
without start_s/end_s lasts the whole run."""
import dataclasses
import tomllib

import pytest

from navtwin.common.schema import Invalid, build
from navtwin.emulator.faults import Fault
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import ScenarioError, load_scenario, parse_scenario, with_faults

from .world_helpers import variant

SC = load_scenario("office")
#: the schedule and the fault's target: set per kind below, not varied
FIXED = {"start_s", "end_s", "repeat_s", "until_s", "port", "direction", "vehicle", "anchor",
         "unit"}
#: candidates from the tiniest float to the largest: each kind keeps those its checks pass
FLOATS = [0.0, 5e-324, 1e-300, 1e-12, 1e-6, 1e-3, 0.5, 1.0, 60.0, 3600.0, 1e6, 1e7, 1e9,
          1e300, 1.7e308]
INTS = [0, 1, 2, 4096, 65536, 2**24, 2**31, 2**62, 2**63 - 1, 10**30]
#: finest schedules that still pass (episodes of 1 us, a period of 1 ms)
SCHEDULES = [{"start_s": 0.0, "end_s": 5e-324}, {"start_s": 1.0, "end_s": 1.0 + 1e-9},
             {"start_s": 0.0, "end_s": 1e-6}, {"start_s": 0.0, "end_s": 1e-6, "repeat_s": 1e-3},
             {"start_s": 0.0, "end_s": 5e-324, "repeat_s": 1e-300},
             {"start_s": 0.0, "end_s": 1e-9, "repeat_s": 2e-9, "until_s": 3.0},
             {"start_s": 9_999_999.0, "end_s": 10_000_000.0}, {}]


def _target(cls) -> dict:
    return {"line": {"port": "xbee"}, "anchor": {"anchor": SC.anchors[0].id}}.get(cls.ACTS_ON, {})


def _accepted(kind: str, spec: dict):
    try:
        return build(Fault, {"kind": kind, **spec})
    except Invalid:
        return None


def _runs(fault) -> None:
    """A short run at max speed with *fault*, through every model and line."""
    with Emulation(dataclasses.replace(SC, faults=(fault,)), 1, speed=None, duration_s=3,
                   ports=False) as emu:
        emu.run()


@pytest.mark.parametrize("kind", list(Fault.KINDS.built_in))
def test_every_setting_that_passes_validation_runs(kind):
    cls = Fault.KINDS.get(kind)
    base = {"start_s": 0.5, "end_s": 2.5, **_target(cls)}
    tried = 0
    for f in dataclasses.fields(cls):
        if f.name in FIXED:
            continue
        ok = [v for v in (INTS if f.type in ("int", int) else FLOATS)
              if _accepted(kind, {**base, f.name: v})]
        for v in {ok[0], ok[1], ok[-1]}:  # the lowest two and the highest accepted
            _runs(_accepted(kind, {**base, f.name: v}))
            tried += 1
    for schedule in SCHEDULES:
        fault = _accepted(kind, {**_target(cls), **schedule})
        if fault is not None:
            _runs(fault)
            tried += 1
    assert tried >= 2


@pytest.mark.parametrize("spec, words", [
    ("bandwidth:port=sins,bytes_per_s=1e-300", "bytes_per_s must be in [1, 1e+07]"),
    ("garbage:port=sins,rate_hz=1e-300", "rate_hz must be in [1e-06, 1e+06]"),
    ("garbage:port=sins,start_s=0,end_s=1e-300", "end_s must be after start_s, by 1e-06 s"),
    ("coordinator_reset:start_s=0,end_s=1e-9,repeat_s=2e-9", "repeat_s must be in [0.001"),
    ("stuck:port=sins,repeat_s=2", "end_s is missing; a repeating fault needs"),
])
def test_values_the_code_cannot_take_are_refused_on_load(spec, words):
    with pytest.raises(ScenarioError) as e:
        with_faults(SC, [spec])
    assert words in str(e.value)


def test_a_fault_without_start_s_and_end_s_lasts_the_whole_run(tmp_path):
    fault, = with_faults(SC, ["bit_errors:port=sins,ber=1e-4"]).faults
    assert (fault.start_s, fault.end_s) == (0.0, 10_000_000.0)
    sc = variant(tmp_path, "office", '[[faults]]\nkind = "byte_drop"\nport = "sins"\n'
                                     'probability = 1.0\n')
    assert sc.faults[0].end_s == 10_000_000.0
    assert parse_scenario(tomllib.loads(sc.to_toml())) == sc  # written as run, read the same
    with Emulation(sc, 1, speed=None, ports=False) as emu:
        summary = emu.run()
    with Emulation(SC, 1, speed=None, ports=False) as emu:
        clean = emu.run()
    assert summary["virtual_s"] == SC.duration_s and summary["ports"]["sins"]["bytes"] == 0
    # every frame of the run was dropped, the first and the last
    assert summary["faults"]["byte_drop"] == {"injections": clean["ports"]["sins"]["frames"],
                                              "bytes": clean["ports"]["sins"]["bytes"]}
