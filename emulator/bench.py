"""Benchmarks of the emulator runtime (not tests: they measure, they do not assert).

``navtwin bench emulator-jitter [--seconds 60] [--scenarios office,outage-bridging]
[--timings fifo,slack,spin]``
    for each scenario in turn, and each in every timing mode of ``--timings`` (emulator.timing),
    in one invocation (one JSON: a row per scenario and mode, and each one's p99s as a ratio
    of the first's: what a field of 1402 anchors costs the real time beside office, what
    each timing mode buys), starts ``navtwin emulate --speed realtime --timing MODE`` (as a
    subprocess, like a user would), reads the ``sins`` port with pyserial and reports how
    regular the SINS frames arrive: p50, p99 and max of |period - nominal| (nominal = 10 ms of
    the board's clock, from the scenario's ppm), frames lost (gaps in seq), drift (the last
    frame's lateness minus the first's, against the absolute schedule t_first + k x nominal),
    and, from a recording of the same run, the emulator's own lateness (write time minus
    scheduled end of each SINS chunk, and the recording's lateness histogram of the port),
    which separates the emulator's jitter from the reader's wake-up latency; and, as the peer
    in the same run, the same reader measure on a bare PTY pair written on an exact schedule
    (``bare_pty``): the floor of the kernel's PTY path on this machine.
``navtwin bench emulator-speed [--scenarios office,corridor] [--repeat 3]``
    generates each whole scenario in virtual time (``--speed max``, no PTYs), without and
    with ``--record``, and reports the real time generated per CPU-second of the loop
    (``Emulation.run``, start-up excluded; medians of the repeats); beside it two floors
    under any loop over these device models, the world alone and each ADIS16350 model alone
    in one call, each as a share of the 1000x goal's CPU (:func:`speed`).
``navtwin bench digi-open [--repeat 10]``
    times digi-xbee's ``XBeeDevice(port, 115200).open()`` on the coordinator's port.
``navtwin bench digi-router [--repeat 10]``
    times digi-xbee's ``RemoteZigBeeDevice.read_device_info()`` on the router, through the
    coordinator (remote AT, then the ZDO node descriptor that gives its role).

``navtwin bench imu-allan [--seconds 7200] [--seed 1]``
    each IMU grade parked for the run, decoded from its SINS bytes (or, for a grade finer
    than an LSB, its registers before quantisation): ARW, VRW and the bias-instability
    floors fitted to allantools' overlapping Allan deviation beside the grade's; and the
    ADIS16350 datasheet's noise table beside the emulator's (docs/emulator-models.md 3.2).

``navtwin bench uart-rx``
    bytes per second the client-UART model (emulator.uart_rx) turns into what a client at
    other settings reads, on 30-byte chunks every 10 ms (the SINS board's frames) for
    several client settings, against the 11 520 B/s a 115200 8N1 line carries.

Each prints one JSON object; a setting left out takes its default (smaller with ``--quick``).
"""
from __future__ import annotations

import os
import select
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navtwin.common.limits import SEEDS
from navtwin.common.schema import Check, between, key, takes

from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import Frame, sins_decoder

from navtwin.protocols.serial import wire_ns

from .timing import NAMES as TIMINGS


def sins_period_ns(scenario: str) -> float:
    """The SINS board's frame period on the wall clock: 10 ms of its clock, at the scenario's
    ppm."""
    from .scenario import load_scenario

    return 10_000_000 / (1 + load_scenario(scenario).clocks.board_ppm * 1e-6)


def jitter(seconds: float = 60.0, scenario: str = "office", seed: int | None = None,
           timing: str = "auto") -> dict:
    """Frame-period jitter seen by a pyserial reader on the ``sins`` port in real time, the
    emulator in timing mode *timing*."""
    import serial

    from .api import emulate

    nominal_ns = sins_period_ns(scenario)
    arrivals: list[int] = []
    seqs: list[int] = []
    dec = sins_decoder()
    tmp = tempfile.TemporaryDirectory(prefix="navtwin-jitter-")
    with tmp, emulate(scenario, seed=seed, speed="realtime", duration=seconds + 2,
                      record=Path(tmp.name) / "rec", timing=timing) as lab:
        with serial.Serial(lab.ports["sins"], 115200, timeout=1.0) as ser:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                data = ser.read(ser.in_waiting or 1)
                t = time.monotonic_ns()
                for ev in dec.feed(data):
                    if isinstance(ev, Frame):
                        arrivals.append(t)
                        seqs.append(ev.fields["seq"])
        lab.stop()
        # the emulator's own lateness: write time minus the scheduled end of each chunk
        rec = Recording(Path(tmp.name) / "rec")
        histogram = rec.meta["lateness"]["sins"]
        late = np.array([c.t_wall_ns - c.t_device_ns - wire_ns(len(c.data), 115200)
                         for c in rec.chunks("sins")]) / 1e6
    t = np.array(arrivals[1:], dtype=np.int64)  # the first read may start mid-frame
    seq = np.array(seqs[1:], dtype=np.int64)
    k = np.cumsum(np.r_[0, (np.diff(seq) % 65536)])
    # against the absolute schedule t_first + k x nominal (the board's counter numbers them)
    stats = period_error(t, t[0] + k * nominal_ns)
    return {"benchmark": "jitter", "scenario": scenario, "timing": lab.info["timing"],
            "seconds": seconds, "frames": int(len(t)),
            "lost": int(k[-1] - (len(k) - 1)), "nominal_ms": nominal_ns / 1e6, **stats,
            "emulator_late_p50_ms": float(np.percentile(late, 50)),
            "emulator_late_p99_ms": float(np.percentile(late, 99)),
            "emulator_late_max_ms": float(late.max()), "emulator_late": histogram,
            # the peer in the same run: a bare PTY pair with exactly timed writes
            "bare_pty": pty_floor(min(len(t), 3000), int(round(nominal_ns)))}


#: drift compares the median lateness of this many frames at each end (one frame's is noise)
DRIFT_FRAMES = 100


def period_errors(arrivals_ns, scheduled_ns) -> np.ndarray:
    """|arrival interval - scheduled interval| of consecutive frames or chunks, in ms."""
    return np.abs(np.diff(np.asarray(arrivals_ns, dtype=np.int64))
                  - np.diff(np.asarray(scheduled_ns, dtype=np.int64))) / 1e6


def period_error(arrival_ns, scheduled_ns) -> dict:
    """How regularly frames arrived, against when they were due: for frames ``i`` read at
    ``arrival_ns[i]`` and scheduled (written, on the writer's schedule) at ``scheduled_ns[i]``,
    in order, the period error of each interval, ``|(a[i+1] - a[i]) - (s[i+1] - s[i])|`` (the
    nominal interval is the schedule's, so irregular streams and skipped frames count
    right), as p50, p99 and max (ms); and the drift, the lateness ``a - s`` of the last
    :data:`DRIFT_FRAMES` frames minus that of the first (medians, ms): a reader falling behind
    the schedule, or a schedule run on a wrong clock. Needs two frames or more."""
    a, s = np.asarray(arrival_ns), np.asarray(scheduled_ns)
    dev = period_errors(a, s)
    late = (a - s) / 1e6
    n = min(DRIFT_FRAMES, len(late))
    return {"p50_ms": float(np.percentile(dev, 50)), "p99_ms": float(np.percentile(dev, 99)),
            "max_ms": float(dev.max()),
            "drift_ms": float(np.median(late[-n:]) - np.median(late[:n]))}


def lateness(arrival_ns, scheduled_ns) -> dict:
    """p50, p99 and max (ms) of ``arrival - scheduled``, the two on one clock."""
    late = (np.asarray(arrival_ns) - np.asarray(scheduled_ns)) / 1e6
    return {"late_p50_ms": float(np.percentile(late, 50)),
            "late_p99_ms": float(np.percentile(late, 99)), "late_max_ms": float(late.max())}


def arrivals(frame_ends, read_ends, read_ns) -> np.ndarray:
    """When each frame arrived: the time of the read that brought its last byte. *frame_ends*:
    each frame's end in the stream (bytes, increasing); *read_ends*, *read_ns*: each read's
    end in the same stream and its time. A frame past the last read gets -1."""
    i = np.searchsorted(np.asarray(read_ends), np.asarray(frame_ends), side="left")
    got = np.r_[np.asarray(read_ns, dtype=np.int64), -1]
    return got[i]


def jitter_beside(seconds: float, scenarios: list[str], timings: list[str] = ("auto",)) -> dict:
    """:func:`jitter` of each scenario in turn, each in every timing mode of *timings*: a row
    each, and each row's reader and emulator p99 as a ratio of the first row's (keyed
    ``scenario/mode``, the mode the run took)."""
    rows = [jitter(seconds, name, timing=mode) for name in scenarios for mode in timings]
    first = rows[0]
    ratio = {f"{r['scenario']}/{r['timing']}": {k: r[k] / first[k]
                                              for k in ("p99_ms", "emulator_late_p99_ms")}
             for r in rows[1:]}
    return {"benchmark": "jitter", "seconds": seconds, "rows": rows, "p99_ratio_to_first": ratio}


FRAME_BYTES = 30  # the bare pair's frame: a SINS frame's size


def _bare_writer(masters: list[int], writes: list[tuple[int, int]]) -> None:
    """Write a frame on ``masters[i]`` at each ``(due_ns, i)`` of *writes* (in order): sleep,
    then spin the last 0.5 ms."""
    frame = b"\x00" * FRAME_BYTES
    for due, i in writes:
        while (left := due - time.monotonic_ns()) > 0:
            if left > 600_000:
                time.sleep((left - 500_000) / 1e9)
        os.write(masters[i], frame)


def nominal_period_ns(ends_ns) -> int:
    """A port's schedule, from its chunks' device ends: the median interval to the ms (the
    SINS board's 10 ms on its clock's ppm, the gateway's 25 ms cycle, the coordinator's
    packets about the routers' 10 ms), the period of the bare pair it is judged against."""
    return int(round(float(np.median(np.diff(np.asarray(ends_ns, dtype=np.int64)))), -6))


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process *pid* has used so far, its threads and its
    descendants included (the emulator's maker process, its workers): each live one's own
    and what its children that ended had used, so a child that ends between two readings
    still counts once."""
    ticks, children = {}, {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:  # it ended meanwhile
                continue
            ticks[int(entry)] = sum(int(f) for f in fields[11:15])  # utime stime cutime cstime
            children.setdefault(int(fields[1]), []).append(int(entry))
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        total += ticks.get(p, 0)
        todo += children.get(p, [])
    return total / os.sysconf("SC_CLK_TCK")


def period_key(period_ns: int) -> str:
    """A bare pair's name in a benchmark's output: its period, ``10 ms``."""
    return f"{period_ns / 1e6:g} ms"


def port_periods(scenario, seed: int | None = None, seconds: float = 2.0) -> dict[str, int]:
    """Each port's schedule (:func:`nominal_period_ns`) in the first *seconds* of *scenario*
    (a Scenario) made in memory: the bare pairs a benchmark runs beside it, one per period."""
    from collections import defaultdict

    from .runner import Emulation

    ends = defaultdict(list)
    with Emulation(scenario, 1 if seed is None else seed, speed=None, duration_s=seconds,
                   ports=False, sink=lambda c: ends[c.port].append(c.end_ns)) as emu:
        emu.run()
    return {port: nominal_period_ns(e) for port, e in ends.items() if len(e) >= 2}


def pty_floor(frames: int = 3000, period_ns: int = 10_000_000) -> dict:
    """The same reader measure on one bare PTY pair (:func:`pty_floors`)."""
    return pty_floors({period_ns: frames})[period_ns]


def pty_floors(frames: dict[int, int]) -> dict[int, dict]:
    """The same reader measure on bare PTY pairs, one per schedule: *frames* maps a period
    (ns) to how many frames its pair carries. A separate process writes 30 bytes on each
    pair at start + k x period (:class:`BarePairs`), this one reads them all
    (:func:`read_pairs`). What is left is the kernel's PTY path and the reader's wake-ups:
    the floor any PTY-based emulator sits on, on this machine, for a port on that schedule
    (a 40 Hz port's p99 is the tail of fewer intervals than a 100 Hz port's, so each is
    judged against a pair of its own rate). Figures per period."""
    with BarePairs(list(frames.items())) as pairs:
        reads = read_pairs(pairs, range(len(frames)))
        return {pairs.periods[i]: pairs.figures(i, r) for i, r in reads.items()}


def read_pairs(pairs: BarePairs, which) -> dict[int, list]:
    """Start *pairs*' writer and read pairs *which* in this process (``select``, then one
    ``read(2)`` of what is there, as the host's port reader does) until each has its frames
    or the writer has stopped: each pair's reads, ``(time ns, bytes)``."""
    fds = {os.open(pairs.paths[i], os.O_RDWR | os.O_NOCTTY): i for i in which}
    want = {r: FRAME_BYTES * pairs.frames[i] for r, i in fds.items()}
    got = dict.fromkeys(fds, 0)
    reads = {r: [] for r in fds}
    pairs.start()
    try:
        while any(got[r] < want[r] for r in fds):
            ready = select.select([r for r in fds if got[r] < want[r]], [], [], 5.0)[0]
            for r in ready:
                n = len(os.read(r, 4096))
                reads[r].append((time.monotonic_ns(), n))
                got[r] += n
            if not ready and not pairs.writing():
                break
    finally:
        for r in fds:
            os.close(r)
    return {i: reads[r] for r, i in fds.items()}


class BarePairs:
    """Bare PTY pairs, each written FRAME_BYTES on its own exact schedule (*pairs*: its
    period and frame count each) by one forked process (:meth:`start`), from a common start
    on this machine's CLOCK_MONOTONIC, so lateness is absolute. Whoever reads them opens
    :attr:`paths` (the pairs' slave ends, raw) and hands the reads to :meth:`figures`: the
    bench's own process, or the very readers of an emulator's ports (emulator.bench_scale:
    a pair read by the same reader as the ports it is the floor of)."""

    LEAD_NS = 100_000_000  # from start() to the first write: the readers are in place

    def __init__(self, pairs: list[tuple[int, int]]):
        import tty

        self.periods = [p for p, _ in pairs]
        self.frames = [n for _, n in pairs]
        self._fds, self.paths = [], []
        for _ in pairs:
            master, slave = os.openpty()
            tty.setraw(slave)
            self._fds += [master, slave]  # the slave held open: bytes wait for a late reader
            self.paths.append(os.ttyname(slave))
        self._writer = None
        self.start_ns = 0

    def start(self) -> None:
        import multiprocessing as mp

        self.start_ns = time.monotonic_ns() + self.LEAD_NS
        writes = sorted((self.start_ns + k * period, i)
                        for i, (period, n) in enumerate(zip(self.periods, self.frames))
                        for k in range(n))
        self._writer = mp.get_context("fork").Process(
            target=_bare_writer, args=(self._fds[0::2], writes))
        self._writer.start()

    def writing(self) -> bool:
        return self._writer is not None and self._writer.is_alive()

    def wait(self) -> None:
        """Until the last write is made."""
        if self._writer is not None:
            self._writer.join()

    def figures(self, i: int, reads) -> dict:
        """Pair *i*'s figures from its reads, ``(time ns, bytes)`` each in order: frames read,
        lost, its period error (:func:`period_error`) and lateness against its schedule."""
        reads = np.asarray(reads, dtype=np.int64).reshape(-1, 2)
        period, n = self.periods[i], self.frames[i]
        k = np.arange(int(reads[:, 1].sum()) // FRAME_BYTES)
        schedule = self.start_ns + k * period
        arrived = arrivals((k + 1) * FRAME_BYTES, np.cumsum(reads[:, 1]), reads[:, 0])
        return {"frames": int(len(k)), "lost": n - int(len(k)), "nominal_ms": period / 1e6,
                **period_error(arrived, schedule), **lateness(arrived, schedule)}

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.wait()
        for fd in self._fds:
            os.close(fd)


#: issue 23's goal for the loop with ``--record``: real time per CPU-second
GOAL_X_REAL_TIME = 1000.0


def speed(scenarios: list[str], repeat: int = 3) -> dict:
    """The ``--speed max`` loop's speed: real time generated per CPU-second, without and with
    ``--record``, for each scenario. CPU time (``time.process_time``: a loaded machine's other
    processes do not count), of :meth:`Emulation.run` only (start-up, ``Emulation(...)``, is
    separate), the median of *repeat* runs; with ``--record`` also the run's last flush
    (:meth:`Emulation.close`, truth.csv up to the end), which a recording needs.

    Beside them, in the same run, two floors under any loop over these device models: the
    ``world`` alone (World.advance and its air over the whole run, in its blocks, with no
    line, port or recording: what every run's loop takes from it), and the ``sensors`` alone
    in one call each (each vehicle's ADIS16350 model, Adis16350.generate over the whole run:
    its draws, filters and the trajectory's kinematics with no per-block cost at all). Each
    floor's ``share_of_goal`` is its CPU over the goal's budget (duration / 1000): at 1 or
    more the goal is out of reach of the models themselves, whatever the loop does."""
    from .runner import Emulation
    from .scenario import load_scenario
    from .world import World

    def timed(make, sc) -> dict:
        """The median CPU of *repeat* runs, each made by ``make()`` (not timed) and run."""
        times = []
        for _ in range(repeat):
            go = make()
            t = time.process_time()
            go()
            times.append(time.process_time() - t)
        cpu = float(np.median(times))
        return {"cpu_s": cpu, "x_real_time_per_cpu_s": sc.duration_s / cpu, "cpu_s_runs": times}

    rows = []
    for name in scenarios:
        sc = load_scenario(name)
        budget = sc.duration_s / GOAL_X_REAL_TIME
        row = {"scenario": name, "virtual_s": sc.duration_s, "goal_cpu_s": budget}
        with tempfile.TemporaryDirectory(prefix="navtwin-speed-") as tmp:
            def loop(record: bool):  # each recording replaces the one before
                emu = Emulation(sc, None, speed=None, ports=False,
                                record=Path(tmp) / "rec" if record else None)
                return lambda: (emu.run(), emu.close())

            row["bare"], row["record"] = timed(lambda: loop(False), sc), timed(lambda: loop(True), sc)

        def world():
            w = World(sc)
            return lambda: (w.advance(sc.duration_ns), w.air(sc.duration_ns))

        def sensors():
            imus = [v.imu for v in World(sc).vehicles]
            return lambda: [imu.generate(0, sc.duration_ns) for imu in imus]

        for label, make in (("world", world), ("sensors", sensors)):
            row[label] = timed(make, sc)
            row[label]["share_of_goal"] = row[label]["cpu_s"] / budget
        rows.append(row)
    return {"benchmark": "speed", "repeat": repeat, "goal_x_real_time": GOAL_X_REAL_TIME,
            "rows": rows}


def digi_open(repeat: int = 10, scenario: str = "office") -> dict:
    """How long digi-xbee's ``XBeeDevice(port, 115200).open()`` takes on the coordinator."""
    from digi.xbee.devices import XBeeDevice

    from .api import emulate

    times = []
    with emulate(scenario, speed="realtime") as lab:
        for _ in range(repeat):
            dev = XBeeDevice(lab.ports["xbee"], 115200)
            t = time.perf_counter()
            dev.open()
            times.append(time.perf_counter() - t)
            role = dev.get_role().description
            dev.close()
    return {"benchmark": "digi-open", "repeat": repeat, "role": role,
            "min_s": min(times), "median_s": float(np.median(times)), "max_s": max(times)}


def digi_router(repeat: int = 10, scenario: str = "office") -> dict:
    """How long digi-xbee's ``read_device_info()`` on the router takes, and the role it got."""
    from digi.xbee.devices import RemoteZigBeeDevice, XBeeDevice
    from digi.xbee.models.address import XBee64BitAddress

    from .api import emulate
    from .scenario import load_scenario

    sc = load_scenario(scenario)
    (router, *_) = sc.routers_for(sc.seed)
    addr64 = XBee64BitAddress((router["SH"] << 32 | router["SL"]).to_bytes(8, "big"))
    times = []
    with emulate(scenario, speed="realtime") as lab:
        dev = XBeeDevice(lab.ports["xbee"], 115200)
        dev.open()
        try:
            for _ in range(repeat):
                remote = RemoteZigBeeDevice(dev, addr64)
                t = time.perf_counter()
                remote.read_device_info()
                times.append(time.perf_counter() - t)
        finally:
            dev.close()
    return {"benchmark": "digi-router", "repeat": repeat, "role": remote.get_role().description,
            "min_s": min(times), "median_s": float(np.median(times)), "max_s": max(times)}


def uart_rx(chunks: int = 3000, seed: int = 1) -> dict:
    """Throughput of Receiver + tty_bytes against the line rate it must keep up with."""
    from .uart_rx import Framing, Receiver, tty_bytes

    line = Framing(115200)
    data = np.random.default_rng(seed).integers(0, 256, (chunks, 30), dtype=np.uint8)
    blobs = [row.tobytes() for row in data]
    out = {}
    for client in (Framing(9600), Framing(57600), Framing(230400), Framing(115200, parity="O"),
                   Framing(115200, bits=7)):
        rx = Receiver(line, client)
        t = time.perf_counter()
        for k, blob in enumerate(blobs):
            tty_bytes(rx.feed(k * 10_000_000, blob), 0)
        out[str(client)] = len(blobs) * 30 / (time.perf_counter() - t)
    line_bps = line.baud / line.frame_bits
    return {"benchmark": "uart-rx", "device": str(line), "chunk_bytes": 30,
            "bytes_per_s": out, "line_bytes_per_s": line_bps,
            "min_x_line": min(out.values()) / line_bps}


@dataclass(frozen=True)
class AllanRuns:
    """imu-allan's settings."""
    seconds: float | None = key(None, "s", "device time of each parked run; none = 7200 (1200 quick)",
                                between(120, 86_400))
    seed: int = key(1, "", "seed of the runs", between(*SEEDS))


def imu_allan(seconds: float, seed: int) -> dict:
    """Each IMU grade's Allan round trip (parked, decoded) and the ADIS16350 datasheet table."""
    from .allan import datasheet_table, markdown, round_trip
    from .imu_errors import GRADES

    grades = [round_trip(g, seconds, seed) for g in GRADES]
    table = datasheet_table(seconds, seed)
    return {"benchmark": "imu-allan", "seconds": seconds, "seed": seed, "grades": grades,
            "datasheet": table, "markdown": markdown(table)}


@dataclass(frozen=True)
class ScenarioRuns:
    """emulator-speed's settings."""
    scenarios: str = key("office,corridor", "", "the scenarios generated, comma-separated names "
                         "or .toml paths")
    repeat: int | None = key(None, "", "runs of each, the median counts; none = 3 (1 quick)",
                             between(1, 1000))


@dataclass(frozen=True)
class RealTime:
    """emulator-jitter's settings."""
    seconds: float | None = key(None, "s", "how long the port is read, per scenario; none = 60 "
                                "(10 quick)", between(1, 3600))
    scenarios: str = key("office", "", "the scenarios run one after another, comma-separated "
                         "names or .toml paths (office,outage-bridging: the field beside office)")
    timings: str = key("auto", "", "the timing modes each scenario runs in, one after another "
                       "(fifo,slack,spin: what each buys)",
                       Check(lambda v: set(v.split(",")) <= set(TIMINGS),
                             f"must be modes of {', '.join(TIMINGS)}, comma-separated",
                             "use e.g. fifo,slack,spin"))


@dataclass(frozen=True)
class Floor:
    """pty-floor's settings."""
    seconds: float | None = key(None, "s", "how long the pairs are written; none = 60 (10 quick)",
                                between(1, 3600))


def floor(seconds: float) -> dict:
    """Bare PTY pairs alone (:func:`pty_floors`), on the SINS board's 10 ms and the gateway's
    25 ms, for *seconds*, with no navtwin code running: what this machine's PTY path and
    scheduler give any program, the floor under every timing goal (issue 22: a maximum
    within 1 ms over 10 minutes is a figure of the machine before it is one of ours)."""
    periods = (10_000_000, 25_000_000)
    got = pty_floors({t: int(seconds * 1e9 / t) for t in periods})
    return {"benchmark": "pty-floor", "seconds": seconds, "load_average": os.getloadavg(),
            "bare_pty": {period_key(t): got[t] for t in periods}}


@dataclass(frozen=True)
class Repeat:
    """digi-open's and digi-router's settings."""
    repeat: int | None = key(None, "", "timed calls, the median counts; none = 10 (3 quick)",
                             between(1, 1000))


def benchmarks() -> dict:
    """The emulator's benchmarks for ``navtwin bench`` (a set of navtwin.cli.bench.SETS)."""
    @takes(ScenarioRuns)
    def emulator_speed(quick: bool, s: ScenarioRuns) -> dict:
        """emulator: --speed max loop, real time per CPU-second, bare and --record, and the models' floors (goal >= 1000x)"""
        return speed(s.scenarios.split(","), repeat=s.repeat or (1 if quick else 3))

    @takes(RealTime)
    def emulator_jitter(quick: bool, s: RealTime) -> dict:
        """emulator: SINS frame-period jitter seen by a pyserial reader, real time (goal p99 <= 0.3 ms)"""
        return jitter_beside(s.seconds or (10.0 if quick else 60.0), s.scenarios.split(","),
                             s.timings.split(","))

    @takes(Floor)
    def pty_floor_alone(quick: bool, s: Floor) -> dict:
        """emulator: bare PTY pairs alone on the 10 and 25 ms schedules, the machine's floor"""
        return floor(s.seconds or (10.0 if quick else 60.0))

    @takes(Repeat)
    def digi_xbee_open(quick: bool, s: Repeat) -> dict:
        """emulator: digi-xbee XBeeDevice.open() on the coordinator (goal < 1.5 s)"""
        return digi_open(s.repeat or (3 if quick else 10))

    @takes(Repeat)
    def digi_xbee_router(quick: bool, s: Repeat) -> dict:
        """emulator: digi-xbee read_device_info() on the router, Role.ROUTER (goal < 2 s)"""
        return digi_router(s.repeat or (3 if quick else 10))

    @takes(AllanRuns)
    def imu_allan_round_trip(quick: bool, s: AllanRuns) -> dict:
        """emulator: IMU grades' Allan round trip from parked bytes, datasheet table (goal within 10 %)"""
        return imu_allan(s.seconds or (1200.0 if quick else 7200.0), s.seed)

    def uart_rx_model(quick: bool = False) -> dict:
        """emulator: client-UART model throughput vs the 11.5 kB/s line (goal >= 5x)"""
        return uart_rx(500 if quick else 3000)

    return {"emulator-speed": emulator_speed, "emulator-jitter": emulator_jitter,
            "digi-open": digi_xbee_open, "digi-router": digi_xbee_router,
            "uart-rx": uart_rx_model, "imu-allan": imu_allan_round_trip,
            "pty-floor": pty_floor_alone}
