"""Every fault kind, in memory (emulator -> UART timing -> host pipeline, no PTY): the host
keeps running, its counters equal the ledger's, the audit of what it read passes, and its
tracks are back within their normal error soon after the episode. The recovery times are
printed (the closing note's table: ``pytest tests/lab/test_fault_kinds.py -s``)."""
import numpy as np
import pytest

from navtwin.emulator.runner import Emulation
from navtwin.emulator.world import World
from navtwin.host import config as host_config
from navtwin.host.arrival import arrivals
from navtwin.host.output import estimate_line
from navtwin.host.pipeline import Pipeline
from navtwin.host.replay import drive, emulator_settings
from navtwin.lab import evaluate
from navtwin.lab.audit import audit_port

from ..emulator.world_helpers import variant

SEED = 3
START, END = 20.0, 24.0  # the episode; the office run is 70 s
SETTLE_S = 5.0  # from the episode's end + this on, a track is within its normal error ...
TOLERANCE = 0.03  # ... but for this fraction of its estimates (the pure WSN has outliers)
#: after a board reset the strapdown realigns over the board's first alignment_s (8 s in the
#: office config) while the vehicle moves on: the fusion tracks ride on WSN fixes till then
SETTLE = {"board_reset": 8.0 + SETTLE_S}


def count(kind):
    return lambda entries, st: sum(e["kind"] == kind for e in entries)


#: kind -> (its [[faults]] settings, {host counter: what the ledger says it must be})
KINDS = {
    "bit_errors": ('port = "xbee"\nber = 1e-4', {}),
    "byte_drop": ('port = "nanoloc"\nprobability = 2e-3', {}),
    "byte_duplicate": ('port = "nanoloc"\nprobability = 2e-3', {}),
    "byte_insert": ('port = "xbee"\nprobability = 1e-3', {}),
    "garbage": ('port = "xbee"\nrate_hz = 5.0', {}),
    "burst_loss": ('port = "nanoloc"', {}),
    "latency": ('port = "nanoloc"\ndelay_s = 0.005\njitter_s = 0.002', {}),
    "bandwidth": ('port = "xbee"\nbytes_per_s = 6000', {}),
    "slicing": ('port = "xbee"\nprobability = 0.5', {}),
    "stuck": ('port = "nanoloc"', {}),
    "link_loss": ("", {}),
    "link_fade": ("attempt_loss = 0.9", {}),
    "anchor_outage": ("anchor = 3", {"timeouts": count("anchor_outage")}),
    "nlos": ("anchor = 2\nbias_m = 0.5", {}),
    "range_value_error": ("anchor = 1\nprobability = 0.5",
                          {"range_errors": count("range_value_error")}),
    "board_reset": ("", {"imu_restarts": count("board_reset")}),
    "coordinator_reset": ("", {"modem_status": lambda entries, st: 2 + 2 * len(entries)}),
    "router_rejoin": ("", {}),
}


def _run(sc):
    kw = emulator_settings(sc.name, {p: dict(v) for p, v in sc.ports.items()},
                           config=host_config.load("office"))
    streams = {p: [] for p in kw["inputs"]}
    sink = lambda c: streams[c.port].append((c.data, c.start_ns)) if c.port in streams else None
    with Emulation(sc, SEED, speed=None, ports=False, sink=sink) as emu:
        emu.run()
    pipe = Pipeline(kw.pop("config"), kw.pop("filters"), **kw)
    estimates: list = []
    drive(pipe, arrivals(streams, {p: sc.ports[p]["baud"] for p in streams}), estimates.extend)
    w = World(sc, SEED)
    tr = w.truth(0, w.duration_ns)
    truth = {"t": tr["t"] / 1e9, "x": tr["x"], "y": tr["y"]}
    errors = {n: (e["t"], evaluate.error(truth, e))
              for n, e in evaluate.load_estimates(map(estimate_line, estimates)).items()}
    return emu.ledger.entries, streams, pipe, errors


def _recovery(t, e, bound, run: int = 3) -> float:
    """Seconds after the episode until the last run of *run* estimates in a row over *bound*
    ends (a lone outlier of the pure WSN is noise, not a track still off)."""
    over = (t >= END) & (e >= bound)
    runs = np.convolve(over, np.ones(run, dtype=int), "valid") == run
    if not runs.any():
        return 0.0
    last = np.flatnonzero(runs)[-1] + run - 1
    return round(float(t[last]) - END + 0.1, 1)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    _, _, _, errors = _run(variant(tmp_path_factory.mktemp("clean"), "office", ""))
    # a track's normal error: twice its p95 after the first 10 s, or its maximum
    return {n: max(2 * float(np.percentile(e[t >= 10], 95)), float(e[t >= 10].max()))
            for n, (t, e) in errors.items()}


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_fault_kind_is_counted_audited_and_recovered_from(tmp_path, clean, kind):
    settings, counters = KINDS[kind]
    sc = variant(tmp_path, "office", f'[[faults]]\nkind = "{kind}"\nstart_s = {START}\n'
                                     f'end_s = {END}\n{settings}\n', name=kind)
    entries, streams, pipe, errors = _run(sc)
    assert entries, f"{kind} injected nothing"
    st = pipe.stats()
    # the host's counters equal the ledger's
    have = {**st["counts"], "imu_restarts": st["vehicles"][0]["imu_clock"]["restarts"]}
    for name, want in counters.items():
        assert have.get(name, 0) == want(entries, st), (name, have.get(name), want(entries, st))
    # the audit of what the host read (in memory it read what the emulator delivered)
    for port, chunks in streams.items():
        r = audit_port(port, b"".join(d for d, _ in chunks), [d for d, _ in chunks], entries,
                       escaped=True)
        assert r.ok, r.problems
    # back within the normal error after the episode (most tracks at once; see the print)
    recovery = {}
    for name, bound in clean.items():
        t, e = errors[name]
        if name == "sins":
            continue  # unaided: it drifts by design (docs/results), no "normal" to return to
        recovery[name] = _recovery(t, e, bound)
        late = t >= END + SETTLE.get(kind, SETTLE_S)
        assert (e[late] >= bound).sum() <= TOLERANCE * late.sum(), (name, recovery)
    reinit = {n: c for n, c in st["vehicles"][0]["estimator"]["reinit"].items()}
    print(f"\n{kind}: ledger {len(entries)} entries; recovery after the episode (s) "
          f"{recovery}; reinit {reinit}")
