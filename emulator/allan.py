"""The Allan round trip of an IMU grade: a parked vehicle's SINS bytes back to ARW, VRW and
the bias-instability floor.

:func:`parked` is the office with the vehicle parked for the whole run and the ``[imu]``
table asked for; :func:`sins_rates` runs it in virtual time (as ``navtwin emulate --speed
max`` does) and decodes the SINS bytes with protocols' decoder into rates; :func:`fit` fits
the overlapping Allan variance (allantools, the oracle) with the three noise terms::

    AVAR(T) = N^2 / T + F^2 + K^2 T / 3

(N the white noise: ARW or VRW; F the flicker floor, flat over 1 .. 3000 s for a flicker
grade; K the rate random walk), least squares weighted by each point's confidence.

What the reads see. The host reads the registers every 10 ms, a sample of the 819.2 SPS
filtered stream: with few taps the reads alias the white noise above 50 Hz, and their ARW is
the sensor's times ``protocols.adis16350.read_white_factor`` (1.19 at the default 4 taps).
The floor, at millihertz, passes unchanged. From 16 taps (-3 dB at 16 Hz, below the reads' 50 Hz) the reads
carry the sensor's own N (factor 1.0003); :data:`SENSOR` is that setting, at +-75 deg/s for
the finest gyro LSB. (More taps smooth the reads over their span, which lowers the Allan
deviation at 1 s by about 2 % at 64 taps.)
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from navtwin.common.schema import build
from navtwin.protocols import adis16350 as adis
from navtwin.protocols import adis16488, sins
from navtwin.protocols.ports import SINS
from navtwin.protocols.stream import Frame, sins_decoder

from .bias import flicker_allan_variance
from .imu import MG, Adis16350, deg_h, ug
from .rng import stream
from .scenario import BLOCK_S, Imu, Scenario, load_scenario
from .trajectory import Trajectory
from .world import World

#: virtual time generated at a time (bounds memory on hours of parked data)
CHUNK_S = 60.0
#: the host's read period of the registers (the board's frame period)
READ_S = sins.PERIOD_S
READ_NS, BLOCK_NS = round(READ_S * 1e9), round(BLOCK_S * 1e9)
#: the [imu] registers under which the reads carry the sensor's own white noise
SENSOR = {"gyro_range_dps": 75, "filter_taps": 16}


def parked(seconds: float, imu: dict, base: str = "office") -> Scenario:
    """*base* with the vehicle parked for *seconds* (its alignment period lasts the whole run)
    and the ``[imu]`` table *imu* (grade, overrides, gyro range, taps; checked as a scenario's)."""
    sc = load_scenario(base)
    return dataclasses.replace(
        sc, name=f"{base}-parked", duration_s=float(seconds), imu=build(Imu, dict(imu), (("imu", 0),)),
        trajectory=dataclasses.replace(sc.trajectory, alignment_s=float(seconds)))


def sins_rates(sc: Scenario, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Gyro (rad/s) and accelerometer (m/s^2) readings (N, 3) of every SINS sample frame of a
    run of *sc*, decoded from the bytes the board writes (protocols' streaming decoder; the
    frame's type says which words: 14-bit, or 32-bit with ``[imu] words = "adis16488"``)."""
    world, dec = World(sc, seed), sins_decoder()
    frames = []
    for t in np.arange(CHUNK_S, sc.duration_s + CHUNK_S, CHUNK_S):
        data = b"".join(e.data for e in world.advance(round(min(t, sc.duration_s) * 1e9))
                        if e.port == SINS.name)
        frames += [f for f in dec.feed(data) if isinstance(f, Frame) and f.type in sins.SAMPLE_TYPES]
    if frames and frames[0].type == sins.TYPE_WIDE_SAMPLE:
        out = adis16488.to_arrays(np.array([f.fields["gyro"] for f in frames]),
                                  np.array([f.fields["accel"] for f in frames]))
    else:
        out = adis.words_to_arrays(np.array([f.fields["words"] for f in frames]), sc.imu.gyro_range_dps)
    return out["gyro_rad_s"], out["accel_m_s2"]


def sensor_rates(sc: Scenario, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """As :func:`sins_rates` (the same sensor: the same streams of *seed*), the registers
    before quantisation, read every READ_S: for a grade finer than the words' LSB, which the
    bytes cannot carry (``paper003``: 0.04 deg/h against 0.018 deg/s = 66 deg/h an LSB, and
    read noise of 0.0008 deg/s, too little to dither it)."""
    imu = Adis16350(sc.imu, sc.site, sc.area, Trajectory(sc.trajectory, sc.tag.z),
                    sc.clocks.imu_ppm, lambda name: stream(seed, name))
    gyro, accel = [], []
    for lo in range(0, sc.duration_ns, BLOCK_NS):
        hi = min(lo + BLOCK_NS, sc.duration_ns)
        imu.generate(lo, hi)
        g, a = imu.outputs(np.arange(-(-max(lo, READ_NS) // READ_NS) * READ_NS, hi, READ_NS))
        gyro.append(g)
        accel.append(a)
    return np.concatenate(gyro), np.concatenate(accel)


def fit(x: np.ndarray, rate: float, taus: np.ndarray, rrw: bool = False) -> dict:
    """Fit AVAR = N^2/T + F^2 a(T) (+ K^2 T/3 with *rrw*) to the overlapping Allan variance of
    the columns of *x* (pooled) at *taus*; a(T) is the flicker bias's exact shape (1 within
    1.3 % over 1 .. 3000 s, less below). Least squares weighted by each point's standard
    error, about AVAR / sqrt(number of tau-intervals in the run), the AVAR of a first fit
    (weights from the measured points themselves would favour the low ones). Returns N, F, K
    (clipped at 0) and the pooled Allan deviation."""
    import allantools

    avar = np.mean([allantools.oadev(x[:, k], rate=rate, data_type="freq", taus=taus)[1] ** 2
                    for k in range(x.shape[1])], axis=0)
    intervals = len(x) / rate / taus
    design = np.column_stack((1.0 / taus, flicker_allan_variance(taus, 1.0), taus / 3.0))
    design = design[:, :3 if rrw else 2]
    model = avar
    for _ in range(2):
        w = np.sqrt(intervals) / model
        coef, *_ = np.linalg.lstsq(design * w[:, None], avar * w, rcond=None)
        coef = np.maximum(coef, 0.0)
        model = np.maximum(design @ coef, 1e-3 * avar)
    n2, f2, k2 = np.append(coef, 0.0)[:3]
    return {"white": math.sqrt(n2), "floor": math.sqrt(f2), "rrw": math.sqrt(k2),
            "taus": taus, "adev": np.sqrt(avar)}


#: ADIS16350 datasheet (Rev. B) Table 1 figures the benchmark sets the model beside:
#: gyro output noise (deg/s rms) per (range, taps); accelerometer output noise unfiltered (mg)
DATASHEET_GYRO_NOISE = {(300, 2): 0.60, (150, 8): 0.35, (75, 32): 0.17}
DATASHEET_ACCEL_NOISE_MG = 35.0
DATASHEET = {"gyro_density_dps_rt_hz": adis.GYRO_NOISE_DENSITY_DPS_RT_HZ,
             "accel_density_mg_rt_hz": adis.ACCEL_NOISE_DENSITY_MG_RT_HZ,
             "arw_deg_rt_h": adis.ARW_DEG_RT_HR, "vrw_m_s_rt_h": adis.VRW_M_S_RT_HR,
             "gyro_floor_dps": adis.GYRO_BIAS_INSTABILITY_DPS,
             "accel_floor_mg": adis.ACCEL_BIAS_INSTABILITY_MG}


def _rel(measured: float, want: float) -> float:
    return measured / want - 1.0 if want else math.nan


def read_lsbs(imu: Imu) -> float:
    """The white noise of a read of the ``[imu]`` table *imu*, in gyro LSBs: above 1 rounding
    adds white noise to it (the words are dithered; below, they stick); above
    :data:`TRANSPARENT`, rounding's LSB/sqrt(12) is below a thousandth of it."""
    taps = adis.bartlett_taps(imu.filter_taps)
    sigma = math.radians(imu.errors.gyro_arw_deg_rt_h) / 60 * math.sqrt(np.sum(taps ** 2) / imu.sample_period_s)
    return sigma / math.radians(imu.word_format.gyro_lsb_dps(imu))


#: read noise in LSBs from which the words are as good as the registers
TRANSPARENT = 300.0


def round_trip(grade: str, seconds: float, seed: int, imu: dict | None = None) -> dict:
    """One grade's Allan round trip: its white noise and floors, the grade's beside the
    measured, with the Allan deviation at 1 .. 1000 s. Read from the bytes at the default 4
    taps where the words are transparent (``[imu] words = "adis16488"``), from the bytes
    with the SENSOR registers where they are dithered, or from the registers before
    quantisation where they stick (``paper003`` in the 14-bit words)."""
    default = parked(seconds, {"grade": grade, **(imu or {})})
    sensor = parked(seconds, {"grade": grade, **SENSOR, **(imu or {})})
    if read_lsbs(default.imu) > TRANSPARENT:
        sc, rates = default, sins_rates
    else:
        sc, rates = (sensor, sins_rates) if read_lsbs(sensor.imu) > 1 else (default, sensor_rates)
    gyro, accel = rates(sc, seed)
    # SENSOR's 16 taps span 38 ms, so its reads are correlated below it: from 0.5 s; the
    # default 4 taps span 8.5 ms, so reads 10 ms apart are independent: from 20 ms
    taus = np.logspace(math.log10(0.5 if sc is sensor else 0.02), math.log10(seconds / 10), 20)
    g, a = fit(gyro, 1 / READ_S, taus), fit(accel, 1 / READ_S, taus)
    e, alias = sc.imu.errors, adis.read_white_factor(sc.imu.filter_taps, 1 / sc.imu.sample_period_s, READ_S)
    rows = {
        "arw_deg_rt_h": (e.gyro_arw_deg_rt_h * alias, math.degrees(g["white"]) * 60),
        "vrw_m_s_rt_h": (e.accel_vrw_m_s_rt_h * alias, a["white"] * 60),
        "gyro_floor_deg_h": (e.gyro_bias_instability_deg_h, math.degrees(g["floor"]) * 3600),
        "accel_floor_ug": (e.accel_bias_instability_ug, a["floor"] / ug(1.0)),
    }
    at = np.array([1.0, 10.0, 100.0, 300.0, 1000.0])
    at = at[at <= seconds / 5]

    def adev(fitted: dict) -> list:
        return np.interp(np.log(at), np.log(taus), fitted["adev"]).tolist()

    return {"grade": grade, "from": "registers" if rates is sensor_rates else "bytes", "seconds": seconds,
            "rows": {k: {"grade": w, "measured": m, "rel": _rel(m, w)} for k, (w, m) in rows.items()},
            "adev_at_s": at.tolist(), "gyro_adev_deg_h": [math.degrees(v) * 3600 for v in adev(g)],
            "accel_adev_ug": [v / ug(1.0) for v in adev(a)]}


def datasheet_table(seconds: float, seed: int) -> list[dict]:
    """The ADIS16350 datasheet's noise figures beside the emulator's (the default grade):
    output noise per range and taps (std of 60 s of reads), noise densities and ARW/VRW of
    the sensor (SENSOR registers) and of the default reads (4 taps every 10 ms), and the
    in-run bias stability (the Allan floor fitted over 0.5 s .. seconds / 10)."""
    rows = []
    for (rng, taps), want in DATASHEET_GYRO_NOISE.items():
        gyro, _ = sins_rates(parked(60.0, {"gyro_range_dps": rng, "filter_taps": taps}), seed)
        rows.append({"figure": f"gyro output noise, +-{rng} deg/s, {taps} taps", "unit": "deg/s rms",
                     "datasheet": want, "emulator": float(np.degrees(gyro.std(axis=0)).mean())})
    _, accel = sins_rates(parked(60.0, {"filter_taps": 1}), seed)
    rows.append({"figure": "accelerometer output noise, no filtering", "unit": "mg rms",
                 "datasheet": DATASHEET_ACCEL_NOISE_MG, "emulator": float(accel.std(axis=0).mean() / MG)})
    sensor = parked(seconds, SENSOR)
    gyro, accel = sins_rates(sensor, seed)
    taus = np.logspace(math.log10(0.5), math.log10(seconds / 10), 20)
    g, a = fit(gyro, 1 / READ_S, taus), fit(accel, 1 / READ_S, taus)
    reads = parked(seconds, {})
    gyro_r, accel_r = sins_rates(reads, seed)
    taus_r = np.logspace(math.log10(0.5), math.log10(60.0), 10)
    gr, ar = fit(gyro_r, 1 / READ_S, taus_r), fit(accel_r, 1 / READ_S, taus_r)
    n_g, n_a = math.degrees(g["white"]), a["white"] / MG  # deg/sqrt(s), mg sqrt(s)
    return rows + [
        {"figure": "gyro rate noise density (one-sided, sqrt(2) N)", "unit": "deg/s/sqrt(Hz)",
         "datasheet": DATASHEET["gyro_density_dps_rt_hz"], "emulator": math.sqrt(2) * n_g},
        {"figure": "accelerometer noise density (one-sided)", "unit": "mg/sqrt(Hz)",
         "datasheet": DATASHEET["accel_density_mg_rt_hz"], "emulator": math.sqrt(2) * n_a},
        {"figure": "ARW of the sensor (16 taps)", "unit": "deg/sqrt(h)",
         "datasheet": DATASHEET["arw_deg_rt_h"], "emulator": 60 * n_g},
        {"figure": "ARW of the 10 ms reads (4 taps)", "unit": "deg/sqrt(h)",
         "datasheet": DATASHEET["arw_deg_rt_h"], "emulator": 60 * math.degrees(gr["white"])},
        {"figure": "VRW of the sensor (16 taps)", "unit": "m/s/sqrt(h)",
         "datasheet": DATASHEET["vrw_m_s_rt_h"], "emulator": 60 * a["white"]},
        {"figure": "VRW of the 10 ms reads (4 taps)", "unit": "m/s/sqrt(h)",
         "datasheet": DATASHEET["vrw_m_s_rt_h"], "emulator": 60 * ar["white"]},
        {"figure": "gyro in-run bias stability (Allan floor)", "unit": "deg/s",
         "datasheet": DATASHEET["gyro_floor_dps"], "emulator": math.degrees(g["floor"])},
        {"figure": "accelerometer in-run bias stability (Allan floor)", "unit": "mg",
         "datasheet": DATASHEET["accel_floor_mg"], "emulator": a["floor"] / MG},
    ]


def markdown(rows: list[dict]) -> str:
    """The datasheet table as docs/emulator-models.md carries it."""
    lines = ["| figure | unit | datasheet | emulator | emulator / datasheet |", "|---|---|---|---|---|"]
    lines += [f"| {r['figure']} | {r['unit']} | {r['datasheet']:.3g} | {r['emulator']:.3g} | "
              f"{r['emulator'] / r['datasheet']:.2f} |" for r in rows]
    return "\n".join(lines)
