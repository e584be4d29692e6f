"""Bad numbers and config values on every command: refused before use with one line, exit 2.

Each case is a ``navtwin`` argv, the files it reads (written into a fresh working directory)
and the words its one line must hold. Each runs as its own process with its temporary and
runtime directories inside that working directory, so that whatever it would create (links,
recordings, estimate files, a lab run directory) shows up: nothing may be created or lost.
The processes are forked from one driver that has imported navtwin once (``DRIVER``): the
same code a user runs, without a second of interpreter start-up per case. Cases that were
accepted before would run; their arguments bound the run (--speed max, short durations,
loop:// ports) and the driver kills a case after a deadline, so a regression fails, never hangs.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from ..helpers import ROOT, navtwin

GOLDEN = str(ROOT / "fixtures" / "golden" / "office")  # a recording replay reads
OFFICE_CONFIG = (ROOT / "host" / "configs" / "office.toml").read_text()

EMULATE = ["emulate", "--speed", "max", "--quiet", "--link-dir", "links"]
PTY = "{pty}"  # a pseudo-terminal's path, opened by the test: what the host's --baud applies to
HOST = ["host", "--xbee", PTY, "--out", "estimates.jsonl", "--duration", "2"]
REPLAY = ["replay", GOLDEN, "--out", "estimates.jsonl"]
DEEP_FAULT = "bit_errors:port=sins,ber=" + "[" * 3000  # RecursionError in tomllib
LONG_FAULT = "bit_errors:port=sins,ber=" + "1" * 5000  # past Python's int digits limit


def emulate(*args: str, scenario: str = "office") -> list[str]:
    return [*EMULATE, "--scenario", scenario, *args]


def scenario_case(toml: str, *words: str, duration: str = "2"):
    """A scenario file based on office with *toml* overriding it."""
    return (emulate("--duration", duration, scenario="s.toml"),
            {"s.toml": 'base = "office"\n' + toml}, words)


def config_text(section: str, line: str) -> str:
    """The office host config with *line* added to [section] (appended when absent)."""
    if f"\n[{section}]\n" in OFFICE_CONFIG:
        return OFFICE_CONFIG.replace(f"\n[{section}]\n", f"\n[{section}]\n{line}\n", 1)
    return OFFICE_CONFIG + f"\n[{section}]\n{line}\n"


def config_case(section: str, line: str, *words: str):
    """``replay`` of a recording with a host config where [section] has *line*."""
    return [*REPLAY, "--config", "c.toml"], {"c.toml": config_text(section, line)}, words


def anchor_case(old: str, new: str, *words: str):
    """The office config with its first anchor's *old* line replaced by *new*."""
    return ([*REPLAY, "--config", "c.toml"], {"c.toml": OFFICE_CONFIG.replace(old, new, 1)},
            words)


CASES = {
    # navtwin emulate
    "emulate --duration nan": (emulate("--duration", "nan"), {}, ["--duration", "finite"]),
    "emulate --duration inf": (emulate("--duration", "inf"), {}, ["--duration", "finite"]),
    "emulate --duration -1": (emulate("--duration", "-1"), {}, ["--duration", "(0, "]),
    "emulate --duration 0": (emulate("--duration", "0"), {}, ["--duration", "(0, "]),
    "emulate --duration 1e300": (emulate("--duration", "1e300"), {}, ["--duration", "1e300"]),
    "emulate --duration 100 (office is 70 s)": (emulate("--duration", "100"), {},
                                                ["--duration", "office"]),
    "emulate --seed -1": (emulate("--seed", "-1", "--duration", "1"), {}, ["--seed", "[0, "]),
    "emulate --seed 2**64": (emulate("--seed", str(2**64), "--duration", "1"), {},
                             ["--seed", str(2**64)]),
    "emulate --seed 1.5": (emulate("--seed", "1.5", "--duration", "1"), {},
                           ["--seed", "integer"]),
    "emulate --speed nan": (emulate("--speed", "nan", "--duration", "1"), {}, ["--speed"]),
    "emulate --speed inf": (emulate("--speed", "inf", "--duration", "1"), {}, ["--speed"]),
    "emulate --speed 0": (emulate("--speed", "0", "--duration", "1"), {}, ["--speed"]),
    "emulate --speed -1": (emulate("--speed", "-1", "--duration", "1"), {}, ["--speed"]),
    "emulate --speed 1e-300": (emulate("--speed", "1e-300", "--duration", "1"), {},
                               ["--speed", "[0.01, 10000]"]),
    # scenario files
    "scenario duration_s = 1e308": scenario_case("duration_s = 1e308\n", "duration_s", "1e+308"),
    "scenario duration_s = nan": scenario_case("duration_s = nan\n", "duration_s", "finite"),
    "scenario duration_s = inf": scenario_case("duration_s = inf\n", "duration_s", "finite"),
    "scenario duration_s = -1": scenario_case("duration_s = -1.0\n", "duration_s"),
    "scenario duration_s = 1e-300": scenario_case("duration_s = 1e-300\n", "duration_s"),
    "scenario seed = -1": scenario_case("seed = -1\n", "seed"),
    "scenario imu.smpl_prd = 255": scenario_case("[imu]\nsmpl_prd = 255\n", "smpl_prd", "<= 179"),
    "scenario imu.filter_taps = 3": scenario_case("[imu]\nfilter_taps = 3\n", "filter_taps"),
    "scenario imu.gyro_arw_deg_rt_h = 1e308": scenario_case("[imu]\ngyro_arw_deg_rt_h = 1e308\n",
                                                            "gyro_arw_deg_rt_h"),
    "scenario imu.accel_bias_corr_s = inf": scenario_case("[imu]\naccel_bias_corr_s = inf\n",
                                                          "accel_bias_corr_s", "finite"),
    "scenario board.baud = 0": scenario_case("[board]\nbaud = 0\n", "[board] baud"),
    "scenario gateway.baud = 10**12": scenario_case("[gateway]\nbaud = 1000000000000\n",
                                                    "[gateway] baud"),
    "scenario xbee.coordinator.BD = 9": scenario_case("[xbee.coordinator]\nBD = 9\n", "BD"),
    "scenario board.start_ms = 1e308": scenario_case("[board]\nstart_ms = 1e308\n", "start_ms"),
    "scenario ranging.start_ms = 1e308": scenario_case("[ranging]\nstart_ms = 1e308\n",
                                                       "[ranging] start_ms"),
    "scenario ranging.sigma0_m = 1e308": scenario_case("[ranging]\nsigma0_m = 1e308\n",
                                                       "sigma0_m"),
    "scenario ranging.sigma_per_m = 1e308": scenario_case("[ranging]\nsigma_per_m = 1e308\n",
                                                          "sigma_per_m"),
    "scenario gateway.latency_us = 1e308": scenario_case("[gateway]\nlatency_us = 1e308\n",
                                                         "latency_us"),
    "scenario link.latency_ms = 1e308": scenario_case("[link]\nlatency_ms = 1e308\n",
                                                      "latency_ms"),
    "scenario link.retry_ms = 1e308": scenario_case("[link]\nretry_ms = 1e308\n", "retry_ms"),
    "scenario tag.z = 1e308": scenario_case("[tag]\nz = 1e308\n", "[tag] z"),
    "scenario trajectory.speed_m_s = 1e308": scenario_case("[trajectory]\nspeed_m_s = 1e308\n",
                                                           "speed_m_s"),
    "scenario area.size = [inf, 7]": scenario_case("[area]\nsize = [inf, 7.0]\n", "size"),
    "scenario area.origin = [1e308, 0]": scenario_case("[area]\norigin = [1e308, 0.0]\n",
                                                       "origin"),
    "scenario anchor x = nan": scenario_case(
        "[[anchors]]\nid = 1\nx = nan\ny = 1.0\n", "[[anchors]] #1 x", "finite"),
    "scenario anchor x = inf": scenario_case(
        "[[anchors]]\nid = 1\nx = inf\ny = 1.0\n", "[[anchors]] #1 x", "finite"),
    "scenario anchor z = 1e308": scenario_case(
        "[[anchors]]\nid = 1\nx = 1.0\ny = 1.0\nz = 1e308\n", "[[anchors]] #1 z"),
    "scenario anchor id = 0": scenario_case("[[anchors]]\nid = 0\nx = 1.0\ny = 1.0\n", "id"),
    "scenario fault start_s = 1e308": scenario_case(
        '[[faults]]\nkind = "link_loss"\nstart_s = 1e308\nend_s = 2e308\n', "start_s"),
    "scenario board_reset on vehicle 7 of 1": scenario_case(
        '[[faults]]\nkind = "board_reset"\nvehicle = 7\nstart_s = 0.0\nend_s = 1.0\n',
        "[[faults]] #1 vehicle 7", "vehicle 1 only"),
    "emulate --fault router_rejoin:vehicle=2": (
        emulate("--duration", "1", "--fault", "router_rejoin:vehicle=2,start_s=0,end_s=1"), {},
        ["--fault", "vehicle 2", "vehicle 1 only"]),
    "scenario fault repeat_s = 1e-9": scenario_case(
        '[[faults]]\nkind = "coordinator_reset"\nend_s = 1e-12\nrepeat_s = 1e-9\n', "repeat_s"),
    # --fault and ctl fault: values a TOML parser cannot take, values the code cannot take
    "--fault ber nested 3000 deep": (emulate("--duration", "1", "--fault", DEEP_FAULT), {},
                                     ["--fault ber", "nested too deeply"]),
    "--fault ber of 5000 digits": (emulate("--duration", "1", "--fault", LONG_FAULT), {},
                                   ["--fault ber", "digits"]),
    "ctl fault ber nested 3000 deep": (["ctl", "--link-dir", "links", "fault", DEEP_FAULT], {},
                                       ["ctl fault ber", "nested too deeply"]),
    "ctl fault ber of 5000 digits": (["ctl", "--link-dir", "links", "fault", LONG_FAULT], {},
                                     ["ctl fault ber", "digits"]),
    "ctl clear of 5000 digits": (["ctl", "--link-dir", "links", "clear", "9" * 5000], {},
                                 ["ctl clear", "a fault id is a number"]),
    "ctl clear ²": (["ctl", "--link-dir", "links", "clear", "\u00b2"], {},
                    ["ctl clear", "a fault id is a number"]),
    "--fault bytes_per_s=1e-300": (emulate("--duration", "1", "--fault", "bandwidth:port=sins,"
                                           "start_s=0,end_s=1,bytes_per_s=1e-300"), {},
                                   ["--fault", "bytes_per_s"]),
    "--fault rate_hz=1e-300": (emulate("--duration", "1", "--fault", "garbage:port=sins,"
                                       "start_s=0,end_s=1,rate_hz=1e-300"), {},
                               ["--fault", "rate_hz"]),
    # navtwin lab
    "lab --duration nan": (["lab", "--duration", "nan", "--dir", "run"], {}, ["--duration"]),
    "lab --seed -1": (["lab", "--seed", "-1", "--dir", "run"], {}, ["--seed"]),
    "lab --filters ''": (["lab", "--filters", "", "--dir", "run"], {}, ["--filters"]),
    # navtwin demo
    "demo --duration nan": (["demo", "--duration", "nan", "--dir", "run"], {}, ["--duration"]),
    "demo --filters ''": (["demo", "--filters", "", "--dir", "run"], {}, ["--filters"]),
    "demo --scenario nowhere": (["demo", "--scenario", "nowhere", "--config", "office",
                                 "--dir", "run"], {}, ["nowhere"]),
    # navtwin sweep
    "sweep --seeds 5..2": (["sweep", "--seeds", "5..2"], {}, ["--seeds", "A <= B"]),
    "sweep --filters kf,nope": (["sweep", "--seeds", "1..2", "--filters", "kf,nope"], {},
                                ["--filters", "nope"]),
    "sweep --scheduler unreachable": (["sweep", "--seeds", "1..2", "--scheduler",
                                       "tcp://127.0.0.1:1"], {}, ["--scheduler", "LocalCluster"]),
    # navtwin calibrate
    "calibrate on a recording that is no calibration walk": (
        ["calibrate", GOLDEN, "--out", "c.toml"], {}, ["f = -0.05286", "no calibration walk"]),
    "calibrate --seeds on a recording": (["calibrate", GOLDEN, "--seeds", "1..3"], {},
                                         ["--seeds", "--scenario"]),
    "calibrate --seeds with --out": (["calibrate", "--scenario", "calibration", "--seeds", "1..3",
                                      "--out", "c.toml"], {}, ["--out", "--seed N"]),
    "calibrate --seeds 3..1": (["calibrate", "--scenario", "calibration", "--seeds", "3..1"], {},
                               ["--seeds", "A <= B"]),
    # navtwin decode
    "decode --baud 0": (["decode", "x.bin", "--format", "sins", "--baud", "0"],
                        {"x.bin": ""}, ["--baud", "[50, 4000000]"]),
    "decode --baud -5": (["decode", "x.bin", "--format", "sins", "--baud", "-5"],
                         {"x.bin": ""}, ["--baud"]),
    "decode --baud 10**12": (["decode", "x.bin", "--format", "sins", "--baud", "1000000000000"],
                             {"x.bin": ""}, ["--baud"]),
    # navtwin diff
    "diff --time-tolerance nan": (["diff", GOLDEN, GOLDEN, "--time-tolerance", "nan"], {},
                                  ["--time-tolerance", "finite"]),
    "diff --time-tolerance -1": (["diff", GOLDEN, GOLDEN, "--time-tolerance", "-1"], {},
                                 ["--time-tolerance"]),
    "diff --max 1.5": (["diff", GOLDEN, GOLDEN, "--max", "1.5"], {}, ["--max", "integer"]),
    "diff on a file that is no recording": (["diff", GOLDEN, "x.bin"], {"x.bin": ""},
                                            ["x.bin", "no recording.json", "--format"]),
    # navtwin pcap
    "pcap on a file that is no recording": (["pcap", "x.bin", "-o", "o.pcapng"], {"x.bin": ""},
                                            ["x.bin", "no recording.json"]),
    "pcap --clock wall of a full-speed run": (["pcap", GOLDEN, "-o", "o.pcapng", "--clock", "wall"],
                                              {}, ["--clock", "no wall times"]),
    "pcap without --out": (["pcap", GOLDEN], {}, ["--out"]),
    "pcap --out in a missing folder": (["pcap", GOLDEN, "-o", "no/o.pcapng"], {},
                                       ["--out no/o.pcapng", "No such file"]),
    # navtwin host
    "host --duration nan": ([*HOST, "--duration", "nan"], {}, ["--duration", "finite"]),
    "host --duration inf": ([*HOST, "--duration", "inf"], {}, ["--duration", "finite"]),
    "host --duration 0": ([*HOST, "--duration", "0"], {}, ["--duration", "(0, "]),
    "host --status-period inf": ([*HOST, "--status-period", "inf"], {}, ["--status-period"]),
    "host --status-period nan": ([*HOST, "--status-period", "nan"], {}, ["--status-period"]),
    "host --status-period 0": ([*HOST, "--status-period", "0"], {}, ["--status-period"]),
    "host --baud 0": ([*HOST, "--baud", "0"], {}, ["--baud", "[50, 4000000]"]),
    "host --baud -5": ([*HOST, "--baud", "-5"], {}, ["--baud"]),
    "host --baud 10**12": ([*HOST, "--baud", "1000000000000"], {}, ["--baud"]),
    "host --baud fast": ([*HOST, "--baud", "fast"], {}, ["--baud", "integer"]),
    "host --filters ''": ([*HOST, "--filters", ""], {}, ["--filters", "no filter"]),
    "host --filters ,": ([*HOST, "--filters", ","], {}, ["--filters", "no filter"]),
    "host --filters kf,pf": ([*HOST, "--filters", "kf,pf"], {}, ["--filters", "'pf'"]),
    "host --config range_bias_m = {1 = 'x'}": (
        [*HOST, "--config", "c.toml"], {"c.toml": config_text("filters", 'range_bias_m = {1 = "x"}')},
        ["range_bias_m"]),
    "replay --filters ''": ([*REPLAY, "--filters", ""], {}, ["--filters"]),
    "replay --filters ,": ([*REPLAY, "--filters", ","], {}, ["--filters"]),
    # host config files
    "config range_bias_m = {1 = 'x'}": config_case("filters", 'range_bias_m = {1 = "x"}',
                                                   "range_bias_m 1", "'x'"),
    "config range_bias_m = {x = 1}": config_case("filters", "range_bias_m = {x = 1}",
                                                 "range_bias_m", "anchor 'x'"),
    "config range_bias_m = {9 = 0.1}": config_case("filters", "range_bias_m = {9 = 0.1}",
                                                   "anchor '9'"),
    "config range_bias_m = {1 = 1e308}": config_case("filters", "range_bias_m = {1 = 1e308}",
                                                     "range_bias_m 1", "[-5, 5]"),
    "config range_bias_m = 1.0": config_case("filters", "range_bias_m = 1.0", "range_bias_m"),
    "config range_bias_m = {1 = {a = 1}}": config_case("filters", "range_bias_m = {1 = {a = 1}}",
                                                       "range_bias_m"),
    "config p0_sigma = [1.0]": config_case("filters", "p0_sigma = [1.0]", "p0_sigma", "3"),
    "config stationary_sigma = [1, 2, 3]": config_case("filters", "stationary_sigma = [1, 2, 3]",
                                                       "stationary_sigma", "2"),
    "config p0_sigma = [nan, 1, 1]": config_case("filters", "p0_sigma = [nan, 1.0, 1.0]",
                                                 "p0_sigma[0]", "finite"),
    "config fix_margin_m = 'x'": config_case("filters", 'fix_margin_m = "x"', "fix_margin_m"),
    "config [filters.ukf] kappa = 'x'": config_case("filters.ukf", 'kappa = "x"', "[filters.ukf] kappa"),
    "config [filters.ukf] alpha = 0": config_case("filters.ukf", "alpha = 0.0", "[filters.ukf] alpha"),
    "config [filters.ukf] alpha = 1e308": config_case("filters.ukf", "alpha = 1e308", "[filters.ukf] alpha"),
    "config range_sigma_m = 1e308": config_case("filters", "range_sigma_m = 1e308",
                                                "range_sigma_m"),
    "config [filters.sins] vrw_m_s_rt_hr = 1e308": config_case("filters.sins", "vrw_m_s_rt_hr = 1e308",
                                                "vrw_m_s_rt_hr"),
    "config output_period_s = 1e-300": config_case("filters", "output_period_s = 1e-300",
                                                   "output_period_s"),
    "config gate_reopen_s = -1": config_case("filters", "gate_reopen_s = -1.0", "gate_reopen_s"),
    "config max_lag_s = -1": config_case("filters", "max_lag_s = -1.0", "max_lag_s"),
    "config altitude_m = 1e308": config_case("filters", "altitude_m = 1e308", "altitude_m"),
    "config x_azimuth_deg = inf": config_case("filters", "x_azimuth_deg = inf", "x_azimuth_deg"),
    "config reference_anchor = 1.5": config_case("filters", "reference_anchor = 1.5",
                                                 "reference_anchor"),
    "config reference_anchor = 9": config_case("filters", "reference_anchor = 9",
                                               "reference_anchor"),
    "config wsn_method = 5": config_case("filters", "wsn_method = 5", "wsn_method"),
    "config enabled = [1]": anchor_case('enabled = ["sins", "wsn", "kf", "ekf", "ukf"]',
                                        "enabled = [1]", "enabled"),
    "config enabled = 5": anchor_case('enabled = ["sins", "wsn", "kf", "ekf", "ukf"]',
                                      "enabled = 5", "enabled"),
    "config enabled = []": anchor_case('enabled = ["sins", "wsn", "kf", "ekf", "ukf"]',
                                       "enabled = []", "enabled"),
    "config latitude_deg = nan": anchor_case("latitude_deg = 34.316", "latitude_deg = nan",
                                             "latitude_deg", "finite"),
    "config local_gravity = inf": anchor_case("local_gravity = 9.7952", "local_gravity = inf",
                                              "local_gravity"),
    "config start = [nan, 0]": anchor_case("start = [6.0, 1.8]", "start = [nan, 0.0]", "start"),
    "config start = [1e308, 0]": anchor_case("start = [6.0, 1.8]", "start = [1e308, 0.0]",
                                             "start"),
    "config heading_deg = 1e308": anchor_case("heading_deg = 0.0", "heading_deg = 1e308",
                                              "heading_deg"),
    "config tag_height = -inf": anchor_case("tag_height = 0.0", "tag_height = -inf",
                                            "tag_height"),
    "config tag = 1.5": anchor_case("tag_height = 0.0", "tag_height = 0.0\ntag = 1.5", "tag"),
    "config router = 5": anchor_case("tag_height = 0.0", "tag_height = 0.0\nrouter = 5",
                                     "router"),
    "config gyro_range_dps = true": anchor_case("gyro_range_dps = 300", "gyro_range_dps = true",
                                                "gyro_range_dps"),
    "config hold_s = nan": config_case("timing", "hold_s = nan", "hold_s"),
    "config anchor x = nan": anchor_case("x = 1.3", "x = nan", "anchor 1 x", "finite"),
    "config anchor x = 'a'": anchor_case("x = 1.3", 'x = "a"', "anchor 1 x"),
    "config anchor x = 1e308": anchor_case("x = 1.3", "x = 1e308", "anchor 1 x"),
    "config anchor z = inf": anchor_case("y = 1.6\n", "y = 1.6\nz = inf\n", "anchor 1 z"),
    "config anchor id = 0": anchor_case("id = 1", "id = 0", "anchor #1 id"),
    "config anchor id = '1'": anchor_case("id = 1", 'id = "1"', "anchor #1 id"),
}


def _tree(d: Path) -> dict[str, bytes | None]:
    """Every path under *d* with a file's content (None for a directory or another kind)."""
    return {str(p.relative_to(d)): p.read_bytes() if p.is_file() and not p.is_symlink() else None
            for p in sorted(d.rglob("*"))}


def prepare(cwd: Path, files: dict[str, str]) -> None:
    """*files* in *cwd*, and the temporary and runtime directories the run will use."""
    cwd.mkdir(exist_ok=True)
    for name, text in files.items():
        (cwd / name).write_text(text)
    for d in ("tmp", "run-user"):
        (cwd / d).mkdir(mode=0o700)


def _env(cwd: Path) -> dict[str, str]:
    return {"TMPDIR": str(cwd / "tmp"), "XDG_RUNTIME_DIR": str(cwd / "run-user")}


def navtwin_in(cwd: Path, argv: list[str]) -> subprocess.CompletedProcess:
    """navtwin run in *cwd* with its temporary and runtime directories there."""
    return navtwin(*argv, cwd=cwd, env={**os.environ, **_env(cwd)}, stdin=subprocess.DEVNULL)


#: Runs each job {"argv", "cwd", "env", "out", "err"} of the JSON on stdin in a forked child
#: (its own process group, stdin /dev/null), as ``navtwin`` would; prints {name: exit status}.
DRIVER = r"""
import json, os, signal, sys, tempfile, time, traceback
from navtwin.cli.main import build_parser, main
build_parser()  # every command's module imported before the forks, and what they load late:
import navtwin.emulator.runner, navtwin.emulator.scenario, navtwin.host.estimator, navtwin.host.replay, navtwin.host.service  # noqa
status = {}
for name, job in json.load(sys.stdin).items():
    pid = os.fork()
    if pid == 0:
        rc = 1
        try:
            os.setpgid(0, 0)
            os.chdir(job["cwd"])
            os.environ.update(job["env"])
            tempfile.tempdir = None  # gettempdir() again, from TMPDIR
            for fd, path, mode in ((0, os.devnull, os.O_RDONLY),
                                   (1, job["out"], os.O_WRONLY | os.O_CREAT),
                                   (2, job["err"], os.O_WRONLY | os.O_CREAT)):
                os.dup2(os.open(path, mode, 0o600), fd)
            try:
                rc = main(job["argv"])
            except SystemExit as e:
                rc = e.code if isinstance(e.code, int) else (e.code is not None)
                if isinstance(e.code, str):
                    print(e.code, file=sys.stderr)
            except BaseException:
                traceback.print_exc()
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(rc)
    deadline = time.monotonic() + 60
    while not (done := os.waitpid(pid, os.WNOHANG))[0] and time.monotonic() < deadline:
        time.sleep(0.01)
    if not done[0]:
        os.killpg(pid, signal.SIGKILL)
        done = os.waitpid(pid, 0)
        status[name] = "killed after 60 s"
    else:
        status[name] = os.waitstatus_to_exitcode(done[1])
json.dump(status, sys.stdout)
"""


def run_all(cases: dict, root: Path, pty: str) -> dict:
    """{case: (exit status, stdout, stderr, tree before, tree after)} for every case, each in
    its own directory under *root*, with *pty* for PTY in its argv."""
    jobs, before = {}, {}
    for i, (name, (argv, files, _)) in enumerate(cases.items()):
        cwd = root / f"case{i}"
        prepare(cwd, files)
        before[name] = _tree(cwd)
        jobs[name] = {"argv": [pty if a == PTY else a for a in argv], "cwd": str(cwd),
                      "env": _env(cwd), "out": str(root / f"case{i}.out"),
                      "err": str(root / f"case{i}.err")}
    ran = subprocess.run([sys.executable, "-c", DRIVER], input=json.dumps(jobs), text=True,
                         capture_output=True, timeout=60 * len(jobs))
    assert ran.returncode == 0, ran.stderr
    status = json.loads(ran.stdout)
    return {name: (status[name], Path(job["out"]).read_text(), Path(job["err"]).read_text(),
                   before[name], _tree(Path(job["cwd"]))) for name, job in jobs.items()}


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    master, slave = os.openpty()  # held open: the host could open and configure it
    try:
        yield run_all(CASES, tmp_path_factory.mktemp("bad-input"), os.ttyname(slave))
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_exit_2_and_touches_nothing(outcomes, case):
    status, out, err, before, after = outcomes[case]
    assert "Traceback" not in err, err
    assert status == 2, (status, err[-2000:])
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    for w in CASES[case][2]:
        assert w in lines[0], lines[0]
    assert after == before  # nothing created, changed or removed


def test_a_one_tap_imu_filter_runs(tmp_path):
    """imu.filter_taps = 1 (SENS/AVG M = 0, no averaging) is a valid device setting: the
    emulator used to crash on it after validation passed."""
    prepare(tmp_path, {"s.toml": 'base = "office"\n[imu]\nfilter_taps = 1\n'})
    result = navtwin_in(tmp_path, emulate("--duration", "2", scenario="s.toml"))
    assert result.returncode == 0, result.stderr[-2000:]
    assert '"done":true' in result.stdout and '"virtual_s":2.0' in result.stdout


def test_the_slowest_valid_sample_rate_and_a_late_board_start_run(tmp_path):
    """smpl_prd = 179 (0.98 s samples, the limit) and a first SINS frame after the run's
    end are accepted and run."""
    prepare(tmp_path, {"s.toml": 'base = "office"\n[imu]\nsmpl_prd = 179\n'
                                 '[board]\nstart_ms = 5000.0\n'})
    result = navtwin_in(tmp_path, emulate("--duration", "3", scenario="s.toml"))
    assert result.returncode == 0, result.stderr[-2000:]
    assert '"virtual_s":3.0' in result.stdout


def test_every_estimator_number_has_a_range_and_docs_state_it():
    from navtwin.host import config as host_config

    table = host_config.markdown_table()
    for row in table.splitlines()[2:]:
        key, unit, default, valid, meaning = (c.strip() for c in row.strip("|").split("|"))
        assert valid, key  # every key's rule is stated
    doc = (ROOT / "docs" / "host.md").read_text()
    assert table in doc


#: Runs ``navtwin`` with the modules of argv[1] (comma list) not installed, as in a wheel
#: installed without the extra that brings them.
WITHOUT = ("import sys\nfor m in sys.argv[1].split(','):\n    sys.modules[m] = None\n"
           "from navtwin.cli.main import main\nsys.exit(main(sys.argv[2:]))")
#: command argv, modules missing, the extra its line must name (demo needs none of its extra
#: off a terminal: plain progress lines, and the run without its plots)
MISSING_EXTRAS = {
    "sweep without pyarrow": (["sweep", "--seeds", "1", "--serial", "--quiet", "--duration", "2",
                               "--filters", "kf", "--out", "o"], "pyarrow", "sweep"),
    "sweep without distributed": (["sweep", "--seeds", "1", "--workers", "1", "--quiet",
                                   "--duration", "2", "--filters", "kf", "--out", "o"],
                                  "distributed", "sweep"),
    "sweep without cryptography": (["sweep", "--seeds", "1", "--workers", "1", "--quiet",
                                    "--duration", "2", "--filters", "kf", "--out", "o"],
                                   "cryptography", "sweep"),
    "sweep without rich": (["sweep", "--seeds", "1", "--serial", "--duration", "2",
                            "--filters", "kf", "--out", "o"], "rich", "sweep"),
    "report without matplotlib": (["report", "run"], "matplotlib", "plot"),
    "bench without digi-xbee": (["bench", "digi-open", "--quick"], "digi", "test"),
    "replay of hinf without cvxpy": (["replay", str(ROOT / "fixtures" / "golden" / "outage-bridging"),
                                      "--config", "outage-bridging", "--filters", "sins,hinf", "--out",
                                      "est.jsonl"], "cvxpy", "lmi"),
}


@pytest.mark.parametrize("case", list(MISSING_EXTRAS))
def test_a_command_whose_extra_is_missing_names_it(tmp_path, case):
    """Installed from a wheel without extras, 'navtwin sweep' ended in ModuleNotFoundError."""
    argv, modules, extra = MISSING_EXTRAS[case]
    prepare(tmp_path, {})
    before = _tree(tmp_path)
    p = subprocess.run([sys.executable, "-c", WITHOUT, modules, *argv], cwd=tmp_path,
                       env={**os.environ, **_env(tmp_path)}, stdin=subprocess.DEVNULL,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and p.stdout == "", p.stderr[-2000:]
    lines = [x for x in p.stderr.splitlines() if not x.startswith("running ")]  # bench's
    assert len(lines) == 1 and f"needs {modules}, which is not installed" in lines[0], lines
    line = lines[0]
    assert f"pip install 'navtwin[{extra}]'" in line, line
    assert _tree(tmp_path) == before  # refused before anything was made
