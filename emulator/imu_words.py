"""The words the IMU's gyro and accelerometer registers are read as, and the SINS frame the
board writes them in: ``[imu] words`` (docs/emulator-models.md section 3.1).

``adis16350`` (the default): the lab's ADIS16350, 14-bit words (protocols.adis16350) whose
gyro LSB the range sets (SENS/AVG: 0.018315 deg/s = 66 deg/h at +-75 deg/s; accelerometer
2.522 mg), in sample frames (type 01).

``adis16488``: 32-bit words as a navigation-grade MEMS IMU gives them (ADIS16488A:
X_GYRO_OUT:X_GYRO_LOW; protocols.adis16488): 0.02 / 2^16 deg/s = 0.0011 deg/h and
0.8 / 2^16 mg = 0.012 ug an LSB, +-450 deg/s, in wide sample frames (type 03). A grade like
003's (0.04 deg/h, 50 ug) is 36 and 4000 LSBs of them; through the 14-bit words it rounds to 0.

Both frames carry the same eleven values in the same order (SUPPLY_OUT, three gyros, three
accelerometers, three temperatures, AUX_ADC), so the IMU's read builds one (M, 11) array of
counts: the housekeeping words are always the ADIS16350's, the six inertial columns the
chosen words'. A new kind of words is one class here and its entry in :data:`WORDS`.
"""
from __future__ import annotations

import numpy as np

from navtwin.protocols import adis16350 as adis
from navtwin.protocols import adis16488 as wide
from navtwin.protocols import sins


class Adis16350Words:
    """14-bit words, ND and EA in every word; the gyro LSB from ``[imu] gyro_range_dps``."""

    frame_size = sins.FRAME_SIZE
    flagged = slice(None)  # the columns that carry ND and EA

    @staticmethod
    def gyro_range_dps(spec) -> float:
        return spec.gyro_range_dps

    @staticmethod
    def gyro_lsb_dps(spec) -> float:
        return adis.GYRO_LSB_DPS[spec.gyro_range_dps]

    @staticmethod
    def inertial(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, spec) -> np.ndarray:
        """(..., 6) words of the gyro (rad/s) and accelerometer (m/s^2) registers (..., 3),
        flags clear."""
        q, p = adis.quantise, adis.pack
        out = np.empty(gyro_rad_s.shape[:-1] + (6,), dtype=np.int64)
        out[..., :3] = p(q(np.degrees(gyro_rad_s), adis.GYRO_LSB_DPS[spec.gyro_range_dps]), 14, nd=False)
        out[..., 3:] = p(q(accel_m_s2 / adis.STANDARD_GRAVITY, adis.ACCEL_LSB_G), 14, nd=False)
        return out

    @staticmethod
    def frames(seq: np.ndarray, words: np.ndarray) -> np.ndarray:
        """The block's sample frames, one a row (protocols.sins.build_samples)."""
        return sins.build_samples(seq, words)


class Adis16488Words:
    """32-bit inertial words (no flag bits: ND and EA ride on the housekeeping words),
    +-450 deg/s whatever ``[imu] gyro_range_dps`` (an ADIS16350 register) says."""

    frame_size = sins.WIDE_FRAME_SIZE
    flagged = [0, 7, 8, 9, 10]  # SUPPLY_OUT, X/Y/ZTEMP_OUT, AUX_ADC

    @staticmethod
    def gyro_range_dps(spec) -> float:
        return wide.GYRO_RANGE_DPS

    @staticmethod
    def gyro_lsb_dps(spec) -> float:
        return wide.GYRO_LSB_DPS

    @staticmethod
    def inertial(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, spec) -> np.ndarray:
        return np.concatenate((wide.counts(np.degrees(gyro_rad_s), wide.GYRO_LSB_DPS),
                               wide.counts(accel_m_s2 / adis.STANDARD_GRAVITY, wide.ACCEL_LSB_G)),
                              axis=-1)

    @staticmethod
    def frames(seq: np.ndarray, words: np.ndarray) -> np.ndarray:
        """The block's wide sample frames, one a row (protocols.sins.build_wide_samples)."""
        return sins.build_wide_samples(seq, words)


#: ``[imu] words``: the kinds of words by name, and the lab's (a scenario that names none)
WORDS = {"adis16350": Adis16350Words, "adis16488": Adis16488Words}
DEFAULT_WORDS = "adis16350"
