"""Hang-ups, many times over: a client closing and reopening each port 100 times, and the
emulator stopped (kill -9 or SIGTERM, in turn) and started again 20 times under a running
host. Everything recovers; the times to recover are printed (the closing note's figures)."""
import io
import signal
import threading
import time

import numpy as np
import pytest
import serial

from navtwin.emulator.api import emulate as emulate_lab
from navtwin.host import config as host_config
from navtwin.host.service import Service
from navtwin.protocols.stream import Frame, XBeeDecoder, nanoloc_decoder, sins_decoder

from .test_restart import NAVTWIN_S, emulate

DECODERS = {"sins": sins_decoder, "xbee": lambda: XBeeDecoder(True), "nanoloc": nanoloc_decoder}
CYCLES = 100
RESTARTS = 20
DEADLINE_S = 20.0


@pytest.mark.pty
@pytest.mark.slow
def test_a_client_closing_and_reopening_each_port_100_times_reads_frames_every_time(tmp_path):
    times = {}
    with emulate_lab("office", link_dir=tmp_path / "links") as lab:
        for port, make in DECODERS.items():
            took = []
            for _ in range(CYCLES):
                t0 = time.monotonic()
                with serial.Serial(lab.ports[port], 115200, timeout=0.05) as ser:
                    dec = make()
                    while not any(isinstance(f, Frame) for f in dec.feed(ser.read(256))):
                        assert time.monotonic() - t0 < DEADLINE_S, f"{port}: no frame after reopen"
                took.append(time.monotonic() - t0)
            times[port] = took
        summary = lab.stop()
    for port, took in times.items():
        assert len(took) == CYCLES
        # it looks for clients every 10 ms, so a close and reopen within that is one attach
        assert summary["ports"][port]["attaches"] >= 1
    print("\nreopen -> first frame (ms) " + ", ".join(
        f"{p}: median {1e3 * np.median(t):.0f}, max {1e3 * max(t):.0f}" for p, t in times.items()))


@pytest.mark.pty
@pytest.mark.slow
def test_twenty_emulator_restarts_under_a_running_host_all_recover(tmp_path):
    links = tmp_path / "links"
    svc = Service({"xbee": str(links / "xbee"), "nanoloc": str(links / "nanoloc")},
                  host_config.load("office"), ("wsn", "ekf"), out=io.StringIO(),
                  status=io.StringIO())
    stop = threading.Event()
    result: dict = {}
    host = threading.Thread(target=lambda: result.update(svc.run(stop)), daemon=True)
    procs, recovery = [], []
    try:
        for n in range(RESTARTS):
            proc, _ = emulate(links, None, None)
            procs.append(proc)
            ready = time.monotonic()
            if n == 0:  # the host starts on the first emulator's ports
                host.start()
                assert svc.started.wait(NAVTWIN_S)
            counts = svc.pipeline.counts
            imu0, reports0 = counts["imu"], counts["reports"]
            # each run outlasts the clock's restart threshold (1 s of counts): a board reset
            # sooner is within a stall's reach and cannot be told from one by its count alone
            while counts["imu"] < imu0 + 150 or counts["reports"] < reports0 + 20:
                assert time.monotonic() - ready < NAVTWIN_S and host.is_alive(), \
                    f"restart {n}: the host got no data from the new emulator"
                time.sleep(0.02)
            recovery.append(time.monotonic() - ready)
            proc.send_signal(signal.SIGKILL if n % 2 == 0 else signal.SIGTERM)
            proc.wait(NAVTWIN_S)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        stop.set()
        host.join(NAVTWIN_S)
    assert not host.is_alive() and result
    assert len(recovery) == RESTARTS
    clocks = result["vehicles"][0]["imu_clock"]
    assert clocks["restarts"] >= RESTARTS - 1  # a new epoch for every run after the first
    print(f"\n{RESTARTS} restarts: emulator ready -> 150 IMU samples and 20 reports at the host "
          f"(s): median {np.median(recovery):.2f}, max {max(recovery):.2f}; "
          f"reconnects {result['reconnects']}")
