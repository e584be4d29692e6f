"""32-bit inertial words of a navigation-grade MEMS IMU (ADIS16488A class) and their units.

The ADIS16488A gives each gyro and accelerometer as a pair of 16-bit registers read as one
32-bit two's complement word: X_GYRO_OUT (upper 16 bits) and X_GYRO_LOW (lower 16), and the
same for Y, Z and for X/Y/Z_ACCL_OUT / _LOW (ADIS16488A data sheet, "Output Data Registers":
X_GYRO_OUT 0.02 deg/s per LSB, X_ACCL_OUT 0.8 mg per LSB, the _LOW word's MSB half an _OUT
LSB; the same scales as Linux's IIO driver adis16480.c, ADIS16488 entry: 450 deg/s =
22500 << 16 counts, 18 g = 22500 << 16 counts).

==================  ====  =================  ==========================================
words               bits  format             LSB
==================  ====  =================  ==========================================
X/Y/Z_GYRO_OUT:LOW  32    two's complement   0.02 / 2^16 deg/s (3.05e-7 deg/s =
                                             1.10e-3 deg/h); range +-450 deg/s
X/Y/Z_ACCL_OUT:LOW  32    two's complement   0.8 / 2^16 mg (1.22e-5 mg = 0.0122 ug);
                                             range +-18 g
==================  ====  =================  ==========================================

The SINS board's wide sample frame (protocols.sins, type 03) carries these six words with
the ADIS16350-format housekeeping words of the sample frame (SUPPLY_OUT, X/Y/ZTEMP_OUT,
AUX_ADC: protocols.adis16350, ND and EA flags in bits 15 and 14). The functions here are the
single conversion: the emulator's to words, the host's from words; ints and numpy integer
arrays alike.
"""
from __future__ import annotations

import math

import numpy as np

from . import adis16350 as adis

#: one LSB of the 32-bit words: the _OUT register's LSB over the 2^16 of the _LOW register
GYRO_LSB_DPS = 0.02 / 65536
ACCEL_LSB_G = 0.8e-3 / 65536
#: the sensor's measurement ranges (beyond: the sensor saturates)
GYRO_RANGE_DPS = 450.0
ACCEL_RANGE_G = 18.0
#: the words' own limits: a value beyond them reads the nearest (saturation)
WORD_MIN, WORD_MAX = -(1 << 31), (1 << 31) - 1
#: the names of the six 32-bit words in frame order (each an _OUT:_LOW register pair)
WORDS = ("X_GYRO", "Y_GYRO", "Z_GYRO", "X_ACCL", "Y_ACCL", "Z_ACCL")


def counts(x, lsb: float):
    """A physical value as a 32-bit word of *lsb*: rounded half away from zero (an ADC code)
    and saturated to the word's range; int or an int64 array."""
    if isinstance(x, np.ndarray):
        v = np.sign(x) * np.floor(np.abs(x) / lsb + 0.5)
        return np.clip(v, WORD_MIN, WORD_MAX).astype(np.int64)
    v = math.floor(abs(x) / lsb + 0.5)
    return min(max(int(math.copysign(v, x)), WORD_MIN), WORD_MAX)


def to_sample(supply: int, gyro, accel, temp, aux: int) -> adis.Sample:
    """Engineering units of a wide sample frame's fields (the host's view of one frame):
    32-bit gyro and accelerometer words, ADIS16350 housekeeping words with their flags."""
    supply_v, temp_c, aux_v = adis.housekeeping(supply, temp, aux)
    nd, ea = adis.flags((supply, *temp, aux))
    return adis.Sample(supply_v=supply_v, gyro_dps=tuple(w * GYRO_LSB_DPS for w in gyro),
                       accel_g=tuple(w * ACCEL_LSB_G for w in accel), temp_c=temp_c, aux_v=aux_v,
                       nd=nd, ea=ea)


def to_arrays(gyro: np.ndarray, accel: np.ndarray) -> dict[str, np.ndarray]:
    """SI units of (N, 3) arrays of 32-bit gyro and accelerometer words."""
    return {"gyro_rad_s": np.asarray(gyro, dtype=np.int64) * math.radians(GYRO_LSB_DPS),
            "accel_m_s2": np.asarray(accel, dtype=np.int64) * (ACCEL_LSB_G * adis.STANDARD_GRAVITY)}


def from_sample(*, gyro_dps, accel_g, temp_c=(25.0, 25.0, 25.0), supply_v=5.0, aux_v=0.0,
                nd: bool = True, ea: bool = False) -> dict:
    """A wide sample frame's fields (less ``seq``) for physical values: the six words
    quantised and saturated, the housekeeping words as the ADIS16350 writes them."""
    kw = {"nd": nd, "ea": ea}
    return {
        "supply": adis.pack(adis.quantise(supply_v, adis.SUPPLY_LSB_V), 12, is_signed=False, **kw),
        "gyro": tuple(counts(v, GYRO_LSB_DPS) for v in gyro_dps),
        "accel": tuple(counts(v, ACCEL_LSB_G) for v in accel_g),
        "temp": tuple(adis.pack(adis.quantise(t - adis.TEMP_ZERO_C, adis.TEMP_LSB_C), 12, **kw)
                      for t in temp_c),
        "aux": adis.pack(adis.quantise(aux_v, adis.AUX_LSB_V), 12, is_signed=False, **kw),
    }
