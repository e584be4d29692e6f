"""navtwin bench timing: the statistics on arrival times whose jitter is known (figures worked
out by hand), the chunk search, the per-port row and the hosts' ports mapped to the
emulator's on recordings made here, and short real-time runs with the host and with a host
per car (counts that add up, no timed assertion)."""
import os
import subprocess
import sys
import time

import pytest

from navtwin.cli.bench import available, settings
from navtwin.cli.main import UsageError
from navtwin.emulator.bench import arrivals, cpu_s, lateness, period_error
from navtwin.lab.timing import fleet_rows, found_ends, port_row, timing
from navtwin.protocols.ports import host_inputs
from navtwin.protocols.recording import Read, Recording, RecordingWriter
from navtwin.protocols.serial import wire_ns

MS = 1_000_000


def test_one_late_frame_makes_two_period_errors_and_no_drift():
    schedule = [k * 10 * MS for k in range(201)]
    arrived = [s + MS + (3 * MS if k == 50 else 0) for k, s in enumerate(schedule)]
    got = period_error(arrived, schedule)
    # 200 intervals: 198 exact, 49->50 and 50->51 off by 3 ms; numpy's p99 of 200 values lies
    # at rank 0.99 x 199 = 197.01, between the last 0 and the first 3: 0.01 x 3 ms
    assert got == {"p50_ms": 0.0, "p99_ms": pytest.approx(0.03), "max_ms": 3.0,
                   "drift_ms": 0.0}  # both ends' median lateness is 1 ms
    assert lateness(arrived, schedule) == {"late_p50_ms": 1.0, "late_p99_ms": 1.0,
                                           "late_max_ms": 4.0}


def test_a_reader_falling_behind_drifts_by_the_difference_of_the_end_medians():
    schedule = [k * 10 * MS for k in range(300)]
    arrived = [s + k * 2_000 for k, s in enumerate(schedule)]  # 2 us later each frame
    got = period_error(arrived, schedule)
    assert got["p50_ms"] == got["p99_ms"] == got["max_ms"] == pytest.approx(0.002)
    # medians of k in 200..299 and in 0..99: (249.5 - 49.5) x 2 us
    assert got["drift_ms"] == pytest.approx(0.4)


def test_an_irregular_schedule_is_its_own_nominal():
    schedule = [0, 10 * MS, 25 * MS, 27 * MS, 40 * MS]  # the gateway's reports, say
    got = period_error([s + 500_000 for s in schedule], schedule)
    assert got == {"p50_ms": 0.0, "p99_ms": 0.0, "max_ms": 0.0, "drift_ms": 0.0}


def test_a_frame_arrives_with_the_read_that_brought_its_last_byte():
    # frames end at bytes 30, 60, 90, 120; reads end at 45 (t=100) and 90 (t=200)
    assert list(arrivals([30, 60, 90, 120], [45, 90], [100, 200])) == [100, 200, 200, -1]


def test_chunks_are_found_in_the_stream_read_after_a_mid_chunk_open_and_a_loss():
    chunks = [b"abcd", b"efgh", b"ijkl", b"mnop"]
    # opened in the middle of abcd; ijkl cut short by the line
    assert found_ends(chunks, b"cd" + b"efgh" + b"ij" + b"mnop") == [None, 6, None, 12]


def _recordings(tmp_path, t0: int, host_t0: int):
    """Ten 10-byte gateway reports every 10 ms from 20 ms on, written 0.1 ms late; the host
    reads each 0.3 ms after its schedule, the seventh 2 ms later still, and never gets the
    fourth."""
    wire = wire_ns(10, 115200)
    emu = RecordingWriter(tmp_path / "emu", {"ports": {"nanoloc": {"baud": 115200}}})
    host = RecordingWriter(tmp_path / "host", {"host": {"inputs": ["nanoloc"]},
                                               "ports": {"nanoloc": {"baud": 115200}}}, reads=True)
    offset = 0
    for k in range(10):
        data = bytes([65 + k]) * 10
        due = (k + 2) * 10 * MS + wire
        emu.port("nanoloc").write(data, (k + 2) * 10 * MS, due + 100_000)
        if k != 3:
            arrival = t0 + due + 300_000 + (2 * MS if k == 6 else 0)
            host.port("nanoloc").write(data, t_wall_ns=arrival - host_t0, read=Read(offset, 0, 0))
            offset += len(data)
    emu.close()
    host.close()
    return Recording(tmp_path / "emu"), Recording(tmp_path / "host")


def test_a_port_row_counts_the_frames_and_times_them_on_one_clock(tmp_path):
    t0, host_t0 = 10**12, 10**12 + 5 * MS  # the host started 5 ms after the emulator
    emu, host = _recordings(tmp_path, t0, host_t0)
    row = port_row(emu, host, "nanoloc", "nanoloc", t0, host_t0, (0, 2**62))
    assert (row["frames_written"], row["frames_read"], row["lost"]) == (10, 9, 1)
    # intervals between the nine read: 3->4 spans the lost one (its own nominal, 20 ms);
    # 5->6 and 6->7 are off by 2 ms, the other six exact
    assert row["p50_ms"] == 0.0 and row["max_ms"] == pytest.approx(2.0)
    assert row["p99_ms"] == pytest.approx(2.0)  # rank 0.99 x 7 = 6.93: between the two 2s
    assert row["drift_ms"] == pytest.approx(0.0)
    assert (row["late_p50_ms"], row["late_max_ms"]) == (pytest.approx(0.3), pytest.approx(2.3))
    assert row["emulator_late_max_ms"] == pytest.approx(0.1)
    # the window takes the chunks scheduled in it: 2, 3 (lost), 4 and 5
    row = port_row(emu, host, "nanoloc", "nanoloc", t0, host_t0, (t0 + 35 * MS, t0 + 75 * MS))
    assert (row["frames_written"], row["frames_read"], row["lost"]) == (4, 3, 1)


def test_seconds_beyond_the_scenario_are_one_line():
    run = available()["timing"]
    with pytest.raises(UsageError, match=r"^--seconds must be at most 60 s for office \(70 s "):
        settings("timing", run.Settings, {"seconds": "65"})


def _host_recording(path, t0: int, reads: dict[str, list[tuple[bytes, int]]]) -> Recording:
    """A host recording started at *t0* (monotonic ns) of *reads*: input -> (data, arrival)."""
    rec = RecordingWriter(path, {"host": {"inputs": list(reads)}, "t0_monotonic_ns": t0,
                                 "ports": {i: {"baud": 115200} for i in reads}}, reads=True)
    for given, got in reads.items():
        offset = 0
        for data, arrival in got:
            rec.port(given).write(data, t_wall_ns=arrival - t0, read=Read(offset, 0, 0))
            offset += len(data)
    rec.close()
    return Recording(path)


def test_each_hosts_inputs_map_its_reads_to_the_emulators_ports(tmp_path):
    """Two cars on networks of their own: host 1 reads nanoloc, host 2 nanoloc2, both as
    ``nanoloc``; each row comes from the right host, keyed by the emulator's name."""
    t0, wire = 10**12, wire_ns(10, 115200)
    emu = RecordingWriter(tmp_path / "emu", {"ports": {p: {"baud": 115200}
                                                       for p in ("nanoloc", "nanoloc2")}})
    host1, host2 = [], []
    for k in range(6):
        for port, got, byte in (("nanoloc", host1, 65), ("nanoloc2", host2, 97)):
            data = bytes([byte + k]) * 10
            emu.port(port).write(data, (k + 1) * 10 * MS, (k + 1) * 10 * MS + wire)
            late = 2 * MS if port == "nanoloc2" else 0  # car 2's host reads 2 ms late
            if (port, k) != ("nanoloc2", 4):  # and never gets its fifth report
                got.append((data, t0 + (k + 1) * 10 * MS + wire + late))
    emu.close()
    hosts = [({"nanoloc": "nanoloc"}, _host_recording(tmp_path / "host", t0 + MS, {"nanoloc": host1})),
             ({"nanoloc": "nanoloc2"}, _host_recording(tmp_path / "host2", t0 + 3 * MS,
                                                       {"nanoloc": host2}))]
    rows = fleet_rows(Recording(tmp_path / "emu"), hosts, t0, (0, 2**62))
    assert list(rows) == ["nanoloc", "nanoloc2"]
    assert [(r["frames_written"], r["frames_read"], r["lost"]) for r in rows.values()] == \
        [(6, 6, 0), (6, 5, 1)]
    # each on its own host's clock: the lateness is 0 and 2 ms, not the hosts' start offsets
    assert rows["nanoloc"]["late_max_ms"] == 0.0
    assert rows["nanoloc2"]["late_p50_ms"] == rows["nanoloc2"]["late_max_ms"] == 2.0
    # host 2's stream has car 2's bytes: had it been read for car 1's port, nothing is found
    wrong = fleet_rows(Recording(tmp_path / "emu"), [({"nanoloc": "nanoloc"}, hosts[1][1])],
                       t0, (0, 2**62))
    assert wrong["nanoloc"]["frames_read"] == 0


def _adds_up(out: dict, ports: set[str], hosts: int, frames: int) -> None:
    """What every run of timing must hold: a row per port, counts, ratios and CPU."""
    assert set(out["ports"]) == ports == set(out["p99_ratio"])
    for name, row in out["ports"].items():
        assert 0 < row["frames_read"] <= row["frames_written"], name
        assert row["lost"] == row["frames_written"] - row["frames_read"], name
        assert row["p99_ms"] >= row["p50_ms"] >= 0 and row["max_ms"] >= row["p99_ms"], name
        peer = out["bare_pty"][out["bare_period"][name]]  # the pair on the port's schedule
        assert out["p99_ratio"][name] == row["p99_ms"] / peer["p99_ms"]
        assert out["late_p99_ratio"][name] == row["late_p99_ms"] / peer["late_p99_ms"]
        assert out["max_over_bare_ms"][name] == row["max_ms"] - peer["max_ms"]
    assert out["worst_p99_ratio"] == max(out["p99_ratio"].values())
    assert out["worst_max_over_bare_ms"] == max(out["max_over_bare_ms"].values())
    assert out["frames_lost_total"] == sum(r["lost"] for r in out["ports"].values())
    # the coordinators' packets on the 10 ms pair, the gateways' reports on the 25 ms one
    assert {p: out["bare_period"][p] for p in ports} == {
        p: "25 ms" if p.startswith("nanoloc") else "10 ms" for p in ports}
    assert {k: (b["frames"], b["lost"]) for k, b in out["bare_pty"].items()} == {
        "10 ms": (frames, 0), "25 ms": (frames * 2 // 5, 0)}
    cpu = out["cpu_cores"]
    assert len(cpu["per_host"]) == out["hosts"] == hosts
    assert cpu["emulator"] >= 0 and min(cpu["per_host"]) >= 0
    assert cpu["host"] == pytest.approx(sum(cpu["per_host"]))


@pytest.mark.pty
@pytest.mark.slow
def test_a_short_run_gives_every_port_the_host_reads_with_counts_that_add_up():
    out = timing(2.5, "office", "auto", "wsn,kf")
    _adds_up(out, {"xbee", "nanoloc"}, 1, 250)
    assert set(out["ports"]) <= set(host_inputs())


@pytest.mark.pty
@pytest.mark.slow
def test_two_cars_on_networks_of_their_own_give_each_cars_ports_from_its_host():
    out = timing(3.0, "office", "auto", "wsn,kf", vehicles=2, network="per-vehicle")
    _adds_up(out, {"xbee", "nanoloc", "xbee2", "nanoloc2"}, 2, 300)
    assert out["vehicles"] == 2
    # each car's coordinator carries its car's 100 Hz SINS stream: 300 packets scheduled in
    # the 3 s window (counted on the device clock), less any the emulator had not written yet
    assert out["ports"]["xbee"]["frames_written"] > 250
    assert out["ports"]["xbee2"]["frames_written"] > 250


def test_network_without_vehicles_is_one_line():
    run = available()["timing"]
    with pytest.raises(UsageError, match=r"^--network says how the vehicles share the air; "
                                         r"give the number of vehicles too$"):
        settings("timing", run.Settings, {"network": "per-vehicle"})


def test_a_host_that_dies_in_the_run_is_one_line_and_exit_status_2(monkeypatch, capsys):
    from navtwin.cli.main import main
    from navtwin.lab import timing as module
    from navtwin.lab.orchestrator import LabError

    def died(*args):
        raise LabError("the host exited during the run (status 1): ValueError: math domain error")

    monkeypatch.setattr(module, "_run", died)
    assert main(["bench", "timing", "--seconds", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == ("navtwin bench: error: timing failed: the host exited during the run "
                       "(status 1): ValueError: math domain error")


def test_cpu_time_counts_the_descendants():
    """A process's CPU in the timing bench counts its descendants' (the emulator's maker
    process): a parent that only waits for a busy grandchild has used what the grandchild
    has, not the few ms of its own start."""
    parent = subprocess.Popen([sys.executable, "-c", "import subprocess, sys; subprocess.run("
                               "[sys.executable, '-c', 'while True: pass'])"])
    busy: list[int] = []
    try:
        deadline = time.monotonic() + 60
        while True:
            busy = [int(p) for p in os.listdir("/proc") if p.isdigit() and _ppid(p) == parent.pid]
            if busy and cpu_s(busy[0]) >= 0.5:
                break
            assert time.monotonic() < deadline, "the busy grandchild never ran"
            time.sleep(0.05)
        assert cpu_s(parent.pid) >= 0.5
    finally:
        for p in busy:
            os.kill(p, 9)
        parent.wait()


def _ppid(pid: str) -> int | None:
    try:
        return int(open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[1])
    except OSError:
        return None
