"""A hand-made lab for the pipeline's tests: bytes with the properties they check.

The real world (:mod:`navtwin.lab.run`) is a moving vehicle; these tests need what it never gives:
a vehicle standing at the config's start (level SINS samples, local gravity on z, seeded
noise of about one LSB) from a board whose crystal runs ``drift_ppm`` fast, each sample in its
own 0x90 packet (API mode 2 or 1) or on the direct line, and four-timestamp exchanges with the
anchors in turn every 25 ms, every 50th a timeout, with the sample counter and the anchors'
``t_us`` starting where the test says (by default just before their wraps).
"""
import math

from navtwin.emulator.rng import stream
from navtwin.host.config import HostConfig
from navtwin.protocols import adis16350, nanoloc, sins, xbee
from navtwin.protocols.serial import wire_ns

ROUTER64 = 0x0013A20040A1B2D4
ROUTER16 = 0x4F2A
BAUD = 115200
EXCHANGE_S = 0.025
REPLY_PS = 100_000_000  # 100 us processing time at each end of an exchange


def _wire_s(n: int) -> float:
    return wire_ns(n, BAUD) / 1e9


def synthetic_chunks(config: HostConfig, seconds: float, *, seed: int = 0, escaped: bool = True,
                     via: str = "xbee", drift_ppm: float = 30.0, start_s: float = 0.05,
                     seq0: int = 65_000, t_us0: int = (1 << 32) - 2_000_000,
                     router64: int = ROUTER64, tag: int = 0x10, vehicle: int = 1,
                     ranging: bool = True):
    """``(port, bytes, arrival ns)`` of a standing vehicle, in arrival order, stamps unique.
    The devices power up at host time *start_s* with counters *seq0* and *t_us0*; the
    vehicle (the config's number *vehicle*) has radio *router64* and tag *tag*; without
    *ranging*, no exchanges."""
    imu_rng, radio_rng, range_rng = (stream(seed, n) for n in ("imu", "radio", "ranges"))
    me = config.vehicles[vehicle - 1]
    g_counts = config.local_gravity / adis16350.STANDARD_GRAVITY
    events = []
    n = int(seconds / sins.PERIOD_S)
    noise = imu_rng.normal(0.0, 1.0, (n, 6))
    glsb, alsb = adis16350.GYRO_LSB_DPS[me.gyro_range_dps], adis16350.ACCEL_LSB_G
    for k in range(n):
        sent = start_s + k * sins.PERIOD_S * (1 + drift_ppm * 1e-6)
        words = adis16350.sample_to_words(gyro_dps=tuple(noise[k, :3] * glsb),
                                          accel_g=(noise[k, 3] * alsb, noise[k, 4] * alsb,
                                                   g_counts + noise[k, 5] * alsb),
                                          gyro_range=me.gyro_range_dps)
        frame = sins.build_sample(seq0 + k, words)
        arrive = sent + _wire_s(sins.FRAME_SIZE)
        if via == "xbee":
            frame = xbee.build(xbee.FrameType.RECEIVE_PACKET, escaped, src64=router64,
                               src16=ROUTER16, options=0x01, data=frame)
            arrive += 0.003 + radio_rng.exponential(0.001) + _wire_s(len(frame))
        events.append((arrive, via, frame))
    x0, y0 = me.start
    ids = sorted(config.anchors)
    for i in range(int(seconds / EXCHANGE_S) if ranging else 0):
        t = start_s + i * EXCHANGE_S
        aid = ids[i % len(ids)]
        ax, ay, az = config.anchors[aid]
        d = math.dist((x0, y0, me.tag_height), (ax, ay, az)) + range_rng.normal(0.0, 0.05)
        if i % 50 == 49:
            status, tau = nanoloc.STATUS_TIMEOUT, (0, 0, 0, 0)
        else:
            tof_ps = round(d / nanoloc.SPEED_OF_LIGHT * 1e12)
            status, tau = nanoloc.STATUS_COMPLETE, (2 * tof_ps + REPLY_PS, REPLY_PS,
                                                    2 * tof_ps + REPLY_PS, REPLY_PS)
        report = nanoloc.build_report(seq=i, t_us=t_us0 + round((t - start_s) * 1e6), anchor=aid,
                                      tag=tag, status=status, rssi=-60, tau=tau)
        events.append((t + 0.0005 + _wire_s(len(report)), "nanoloc", report))
    last = -1
    for arrive, port, data in sorted(events, key=lambda e: e[0]):
        last = max(round(arrive * 1e9), last + 1)
        yield port, data, last
