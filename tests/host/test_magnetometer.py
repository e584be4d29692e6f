"""The magnetometer heading checked against truth (issue 20, Must show): an emulated run with
the magnetometer on, its frames decoded from the recorded bytes, the heading of
host.magnetometer against truth.csv's yaw, compared with what the configured noise and hard
iron predict; and the host's MagSample records from the same bytes."""
import dataclasses
import math

import numpy as np
import pytest

from navtwin.common import geomagnetic, lab
from navtwin.emulator.imu import body_from_nav
from navtwin.emulator.runner import Emulation
from navtwin.emulator.scenario import Magnetometer, load_scenario
from navtwin.host.estimator import Estimator
from navtwin.host.magnetometer import yaw_from_field
from navtwin.host.measurements import ImuSample, MagSample
from navtwin.host.pipeline import Pipeline
from navtwin.host.replay import replay
from navtwin.protocols import sins
from navtwin.protocols.recording import Recording
from navtwin.protocols.stream import sins_decoder

from ..helpers import OFFICE

LAB = (lab.LATITUDE_DEG, lab.LONGITUDE_DEG)


class Capture:
    """An estimator that keeps the records it is fed."""

    def __init__(self, records: list) -> None:
        self.records = records

    def feed(self, r) -> list:
        self.records.append(r)
        return []

    def stats(self) -> dict:
        return {}


def horizontal_ut() -> float:
    north, east, _ = geomagnetic.field_ned(*LAB)
    return math.hypot(north, east)


def run(tmp_path, seconds: float, **magnetometer) -> Recording:
    sc = load_scenario("office")
    sc = dataclasses.replace(sc, magnetometer=Magnetometer(enabled=True, **magnetometer))
    with Emulation(sc, 11, speed=None, ports=False, duration_s=seconds,
                   record=tmp_path / "run") as emu:
        emu.run()
    return Recording(tmp_path / "run")


def heading_errors(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(true yaw, magnetometer yaw - true yaw) in rad at each magnetometer frame of the
    recorded SINS line; the frame's seq gives its read time (board: first frame at
    start_ms, every period_ms, registers read spi_read_us before)."""
    frames = [e for e in sins_decoder().decode(rec.read_bytes("sins"))
              if e.type == sins.TYPE_MAGNETOMETER]
    board = load_scenario("office").board
    seq = np.array([f.fields["seq"] for f in frames])
    t_read = (board.start_ms + seq * board.period_ms) * 1e6 - board.spi_read_us * 1e3
    truth = np.genfromtxt(rec.directory / "truth.csv", delimiter=",", names=True)
    yaw = np.interp(t_read, truth["t"], np.unwrap(truth["yaw"]))
    measured = np.array([yaw_from_field(sins.field_ut(f.fields["field"]), lab.DECLINATION_DEG,
                                        lab.X_AZIMUTH_DEG) for f in frames])
    return yaw, np.angle(np.exp(1j * (measured - yaw)))


def test_noise_alone_gives_noise_over_the_horizontal_field(tmp_path):
    noise = 0.5
    _, err = heading_errors(run(tmp_path, 30.0, noise_ut=noise))
    assert len(err) == 300  # 10 Hz for 30 s
    quantum = sins.MAG_LSB_UT / math.sqrt(12)
    predicted = math.hypot(noise, quantum) / horizontal_ut()  # rad, small-angle
    assert err.std() == pytest.approx(predicted, rel=0.1)
    assert abs(err.mean()) < 4 * predicted / math.sqrt(len(err))


def test_hard_iron_gives_asin_h_over_b_over_a_turn(tmp_path):
    hard = 6.0  # uT along the body's x: the error follows the heading
    yaw, err = heading_errors(run(tmp_path, 70.0, noise_ut=0.05, hard_iron_ut=(hard, 0.0, 0.0)))
    assert np.ptp(yaw) > 1.9 * math.pi  # the loop turns the vehicle through every heading
    bound = math.asin(hard / horizontal_ut())
    assert np.abs(err).max() == pytest.approx(bound, abs=math.radians(0.5))
    # the error at each heading: the field seen from the body with the hard iron added
    magnetic_north = math.radians(lab.X_AZIMUTH_DEG - lab.DECLINATION_DEG)
    rel = magnetic_north - yaw  # where magnetic north lies, counter-clockwise from body x
    seen = np.angle(horizontal_ut() * np.exp(1j * rel) + hard)
    predicted = np.angle(np.exp(1j * (rel - seen)))
    assert np.abs(err - predicted).std() < math.radians(0.3)


def test_soft_iron_gives_asin_k_at_twice_the_heading_rate(tmp_path):
    k = 0.05  # the body x axis reads 5 % high, y 5 % low: an ellipse of axes 1 +- k
    soft = ((1 + k, 0.0, 0.0), (0.0, 1 - k, 0.0), (0.0, 0.0, 1.0))
    yaw, err = heading_errors(run(tmp_path, 70.0, noise_ut=0.05, soft_iron=soft))
    assert np.abs(err).max() == pytest.approx(math.asin(k), abs=math.radians(0.3))
    rel = math.radians(lab.X_AZIMUTH_DEG - lab.DECLINATION_DEG) - yaw
    seen = np.arctan2((1 - k) * np.sin(rel), (1 + k) * np.cos(rel))
    predicted = np.angle(np.exp(1j * (rel - seen)))
    assert np.abs(err - predicted).std() < math.radians(0.3)


def test_the_host_makes_one_mag_sample_per_frame_at_its_samples_time(tmp_path):
    rec = run(tmp_path, 5.0)
    records = []
    pipe = replay(rec, lambda es: None, make_estimator=lambda _: Capture(records))
    mags = [r for r in records if isinstance(r, MagSample)]
    assert len(mags) == 50 and pipe.counts["magnetometer"] == 50
    for before, r in zip(records, records[1:]):  # each at the time of the sample it follows
        if isinstance(r, MagSample):
            assert isinstance(before, ImuSample) and before.t == r.t
    assert pipe.counts["magnetometer_untimed"] == 0


@pytest.mark.parametrize("roll, pitch, yaw", [(0.0, 0.0, 0.3), (0.2, -0.1, 2.5),
                                              (-0.3, 0.25, -1.2), (0.1, 0.4, math.pi)])
def test_tilt_compensation_undoes_the_attitude(roll, pitch, yaw):
    azimuth = 70.0
    north, east, down = geomagnetic.field_ned(*LAB)
    a = math.radians(azimuth)
    field_n = (north * np.array([math.cos(a), math.sin(a), 0.0])
               + east * np.array([math.sin(a), -math.cos(a), 0.0]) + np.array([0.0, 0.0, -down]))
    # declination given as the model's, so the heading comes back exactly
    declination = math.degrees(math.atan2(east, north))
    m = body_from_nav(np.array([roll]), np.array([pitch]), np.array([yaw]))[0] @ field_n
    got = yaw_from_field(m, declination, azimuth, roll, pitch)
    assert math.remainder(got - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


def test_a_frame_without_its_sample_has_no_time():
    """A magnetometer frame whose sample frame was lost (or a second copy of one) is counted,
    not given a time it does not have."""
    records = []
    pipe = Pipeline(OFFICE, make_estimator=lambda _: Capture(records), inputs=("sins",))
    words = [0x8000] * 11
    data = (sins.build_sample(1, words) + sins.build_magnetometer(1, (100, 0, -400))
            + sins.build_magnetometer(1, (100, 0, -400))  # a second copy
            + sins.build_magnetometer(2, (100, 0, -400))  # its sample frame lost
            + sins.build_sample(3, words) + sins.build_magnetometer(3, (-4096, 0, 0)))  # overflow
    pipe.feed("sins", data, 50_000_000)
    pipe.finish()
    assert [type(r).__name__ for r in records] == ["ImuSample", "MagSample", "ImuSample"]
    assert records[1].field == pytest.approx((100 * sins.MAG_LSB_UT, 0.0, -400 * sins.MAG_LSB_UT))
    assert (pipe.counts["magnetometer"], pipe.counts["magnetometer_untimed"],
            pipe.counts["magnetometer_overflow"]) == (1, 2, 1)


def test_an_estimator_whose_tracks_take_no_mag_samples_counts_them():
    est = Estimator(OFFICE.estimator_config(("sins", "kf")))
    est.feed(ImuSample(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 9.8)))
    assert est.feed(MagSample(0.0, (0.0, 30.0, -40.0))) == []
    assert est.input_rejections["MagSample_untaken"] == 1
