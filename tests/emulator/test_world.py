"""The World: determinism, independence from how time is sliced, event order, truth output,
and the virtual-time generation speed (a benchmark, not a timed assertion)."""
import numpy as np
import pytest

from navtwin.emulator.scenario import SCENARIO_NAMES, load_scenario
from navtwin.emulator.truth import DTYPE, FIELDS, PLACES, csv_rows, read_truth_csv, write_truth_csv
from navtwin.emulator.maker import MakerError
from navtwin.emulator.world import EVENT_ORDER, Event, RfPacket, World

from .world_helpers import port_bytes


@pytest.fixture(scope="module")
def office_events():
    sc = load_scenario("office")
    w = World(sc)
    return sc, w.advance(w.duration_ns)


def test_same_seed_identical_events(office_events):
    sc, events = office_events
    again = World(sc).advance(10**12)
    assert again == events


def test_different_seed_different_bytes_on_every_port(office_events):
    sc, events = office_events
    other = World(sc, sc.seed + 1).advance(10**12)
    for port in ("sins", "nanoloc"):
        a, b = port_bytes(events, port), port_bytes(other, port)
        assert a != b and len(a) == len(b)
    assert [e.data.data for e in events if e.port == "xbee"][:50] != \
        [e.data.data for e in other if e.port == "xbee"][:50]


@pytest.mark.parametrize("slicing", ["1ms", "random", "blocks"])
def test_slicing_never_changes_the_events(office_events, slicing):
    sc, events = office_events
    w = World(sc)
    rng = np.random.default_rng(4)
    got, t = [], 0
    horizon = 12_000_000_000  # enough to cross block boundaries many ways
    while t < horizon:
        step = {"1ms": 1_000_000, "blocks": World.BLOCK_NS,
                "random": int(rng.integers(1, 400_000_000))}[slicing]
        t = min(t + step, horizon)
        got += w.advance(t)
    got += w.advance(10**12)
    assert got == events


def test_events_are_ordered_and_within_the_run(office_events):
    sc, events = office_events
    keys = [(e.t_ns, EVENT_ORDER.index(e.port)) for e in events]
    assert keys == sorted(keys)
    assert all(0 <= e.t_ns < sc.duration_ns for e in events)
    assert {e.port for e in events} == set(EVENT_ORDER)
    assert all(isinstance(e, Event) for e in events)
    assert all(isinstance(e.data, RfPacket) for e in events if e.port == "xbee")
    assert all(isinstance(e.data, bytes) for e in events if e.port != "xbee")


def test_advance_returns_each_event_once(office_events):
    sc, events = office_events
    w = World(sc)
    first = w.advance(2_000_000_000)
    assert w.advance(2_000_000_000) == [] and w.advance(1_000_000_000) == []
    assert first == [e for e in events if e.t_ns < 2_000_000_000]
    assert not w.finished
    rest = w.advance(w.duration_ns)
    assert first + rest == events and w.finished


def test_uart_lines_never_overlap(office_events):
    """A port writes one frame at a time at its baud: starts are at least a frame apart."""
    sc, events = office_events
    for port, size in (("sins", 30), ("nanoloc", 32)):
        t = np.array([e.t_ns for e in events if e.port == port])
        assert np.all(np.diff(t) >= size * 10 / 115200 * 1e9 - 1)


@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_every_shipped_scenario_runs(name):
    sc = load_scenario(name)
    w = World(sc)
    events = w.advance(3_000_000_000)
    assert {e.port for e in events} == set(sc.ports)  # every port of every car has events


def test_truth_csv_round_trip(tmp_path):
    sc = load_scenario("office")
    w = World(sc)
    path = tmp_path / "truth.csv"
    rows = write_truth_csv(path, w)
    assert rows == round(sc.duration_s * 1000)
    header = path.read_text().splitlines()[0]
    assert header == ",".join(FIELDS)
    back = read_truth_csv(path)
    truth = w.truth(0, w.duration_ns)
    assert np.array_equal(back["t"], truth["t"])
    for f in FIELDS[1:]:
        assert np.allclose(back[f], truth[f], atol=1e-6), f
    part = tmp_path / "part.csv"
    assert write_truth_csv(part, w.truth(1_500_000, 5_000_000)) == 3  # 2, 3 and 4 ms


def test_truth_text_is_printf_number_by_number():
    """csv_rows' whole-array text equals printf's ("%d", "%.6f", "%.9f") for every number:
    halves at the last place (rounded to even on the exact binary value), values just either
    side of them, -0.0 and negatives that round to zero, every integer width, and what it
    hands to printf (nan, inf, too large)."""
    rng = np.random.default_rng(23)
    arr = np.zeros(6000, DTYPE)
    arr["t"] = rng.integers(-10**13, 10**13, len(arr))
    arr["t"][:3] = 0, 7, -1
    for f in FIELDS[1:]:
        arr[f] = rng.standard_normal(len(arr)) * 10.0 ** rng.integers(-12, 12, len(arr))
    halves = (np.arange(1000) - 500 + 0.5) / 1e6
    arr["x"][:1000] = halves  # ties at six places, as the nearest doubles
    arr["x"][1000:2000] = np.nextafter(halves, np.inf)
    arr["yaw"][2000:3000] = (np.arange(1000) - 500 + 0.5) / 2**30  # exact halves at nine places
    arr["yaw"][3000:4000] = (np.arange(1000) - 500) / 8  # exact binary fractions
    arr["y"][4000:4004] = -0.0, -4e-7, -4e-10, 999.9999996
    arr["z"][4004:4008] = np.nan, np.inf, -np.inf, 1e300
    fmt = ["%d" if p == 0 else f"%.{p}f" for p in PLACES]
    expect = "".join(",".join(f % v for f, v in zip(fmt, row)) + "\n" for row in arr.tolist())
    assert csv_rows(arr).decode() == expect
    assert b"".join(csv_rows(arr[i:i + 700]) for i in range(0, len(arr), 700)) == csv_rows(arr)


def test_truth_slices_agree():
    sc = load_scenario("corridor")
    w = World(sc)
    whole = w.truth(0, 20_000_000_000)
    parts = np.concatenate([w.truth(t, t + 3_000_000_000) for t in range(0, 20_000_000_000, 3_000_000_000)])
    assert np.array_equal(whole[:len(parts)], parts[:len(whole)])


@pytest.mark.benchmark(group="world")
def test_office_virtual_time_speed(benchmark):
    """Generation speed of the whole office run; goal >= 300x real time
    (pytest tests/emulator/test_world.py --benchmark-only)."""
    sc = load_scenario("office")

    def generate():
        w = World(sc)
        return len(w.advance(w.duration_ns))

    n = benchmark.pedantic(generate, rounds=5, iterations=1, warmup_rounds=1)
    assert n > 16000
    benchmark.extra_info["real_time_factor"] = sc.duration_s / benchmark.stats.stats.min


def test_board_and_network_clocks_follow_their_crystals(tmp_path):
    """Frame k at start + round(k x 10 ms / (1 + ppm)) (absolute schedule, no drift of the
    rounding); cycle c of the anchors at 5 ms + c x 100 ms of the network clock."""
    from .world_helpers import variant
    sc = variant(tmp_path, "office", "duration_s = 30.0\n[clocks]\nboard_ppm = 50.0\nnetwork_ppm = -30.0\n")
    events = World(sc).advance(10**12)
    t = np.array([e.t_ns for e in events if e.port == "sins"])
    k = np.arange(len(t))
    assert np.array_equal(t, 1_000_000 + np.rint(k * 1e7 / (1 + 50e-6)).astype(np.int64))
    assert len(t) == 3001  # 1 ms + k x 9.9995 ms < 30 s for k = 0..3000
    from .world_helpers import reports
    r = reports(events)
    first = r["t_ns"][r["anchor"] == 1]
    gaps = np.diff(first)  # each report is written a fixed time after its exchange
    assert np.allclose(gaps, 1e8 / (1 - 30e-6), atol=2e3)  # 20 ns jitters, rounding


def test_device_truth_is_plain_data():
    import json
    sc = load_scenario("office")
    w = World(sc, 3)
    info = json.loads(json.dumps(w.device_truth()))
    assert info["router_my"] == sc.radios_for(3)["router"]["MY"] == w.vehicles[0].src16
    assert len(info["imu"]["gyro"]["turn_on_bias"]) == 3 and len(info["imu"]["accel"]["matrix"]) == 3


def test_blocks_made_ahead_by_the_maker_process_are_the_blocks_made_in_turn(office_events):
    """World.ahead's maker process makes the same events and air frames as the World alone,
    taken in slices that do not fall on blocks, and what a step raises there is raised by
    advance with the child's traceback (never a loop waiting for a block that will not come)."""
    sc, events = office_events
    world = World(sc)
    got = world.advance(World.BLOCK_NS // 3)  # made here, before the fork: not sent twice
    with world.ahead():
        for k in range(1, 22):
            got += world.advance(k * World.BLOCK_NS // 3)
    assert got == [e for e in events if e.t_ns < 7 * World.BLOCK_NS] and got

    broken = World(sc)
    imu = broken.vehicles[0].imu
    generate = imu.generate

    def failing(lo, hi):
        if lo >= 2 * World.BLOCK_NS:
            raise ArithmeticError("a model's step failed")
        return generate(lo, hi)
    imu.generate = failing
    with broken.ahead(), pytest.raises(MakerError, match="ArithmeticError: a model's step failed"):
        for k in range(1, 8):
            broken.advance(k * World.BLOCK_NS)
