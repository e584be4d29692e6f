"""The SINS board's frames over RS-232 (wire-formats.md section 1; docs/protocols.md).

Sample frame (type 01): the ADIS16350 register words, one every 10 ms of the board's clock.

| offset | size | field | value                                                   |
|--------|------|-------|---------------------------------------------------------|
| 0      | 2    | sync  | ``A5 5A``                                               |
| 2      | 1    | type  | ``01`` = sample (others reserved, skipped by ``len``)   |
| 3      | 1    | len   | ``18`` (24) for type 01                                 |
| 4      | 2    | seq   | sample counter, +1 per sample, 65535 wraps to 0         |
| 6      | 22   | words | 11 raw register words, SUPPLY_OUT .. AUX_ADC            |
| 28     | 2    | crc   | CRC-16/CCITT-FALSE over bytes 2..27                      |

30 bytes, 2.604 ms on the wire at 115200 8N1.

Magnetometer frame (type 02), interleaved when the vehicle carries a magnetometer: written
right after the sample frame of the tick at which the DSP read the magnetometer.

| offset | size | field | value                                                   |
|--------|------|-------|---------------------------------------------------------|
| 0      | 2    | sync  | ``A5 5A``                                               |
| 2      | 1    | type  | ``02`` = magnetometer                                   |
| 3      | 1    | len   | ``08``                                                  |
| 4      | 2    | seq   | the sample counter of the sample frame it follows       |
| 6      | 6    | field | x, y, z body axes, signed 16 bit, LSB = MAG_LSB_UT      |
| 12     | 2    | crc   | CRC-16/CCITT-FALSE over bytes 2..11                      |

14 bytes. The words are a Honeywell HMC5883L's data output registers at its default gain
(CRB GN = 001: 1090 LSB/gauss, so 0.09174 uT/LSB; 12-bit data -2048..2047, -4096 on
overflow; datasheet Rev. E, Table 9), which the DSP reads over I2C in the chip's X, Z, Y
register order and writes in body order x, y, z (x forward, y left, z up).

Wide sample frame (type 03), instead of type 01 when the scenario's IMU speaks 32-bit
inertial words (``[imu] words = "adis16488"``; protocols.adis16488): the same sample, its
gyro and accelerometer words 32 bits wide.

| offset | size | field  | value                                                   |
|--------|------|--------|---------------------------------------------------------|
| 0      | 2    | sync   | ``A5 5A``                                               |
| 2      | 1    | type   | ``03`` = wide sample                                    |
| 3      | 1    | len    | ``24`` (36)                                             |
| 4      | 2    | seq    | sample counter, as type 01's                            |
| 6      | 2    | supply | SUPPLY_OUT, as in type 01                               |
| 8      | 12   | gyro   | X, Y, Z_GYRO_OUT:LOW, signed 32 bit, 0.02/2^16 deg/s    |
| 20     | 12   | accel  | X, Y, Z_ACCL_OUT:LOW, signed 32 bit, 0.8/2^16 mg        |
| 32     | 6    | temp   | X, Y, ZTEMP_OUT, as in type 01                          |
| 38     | 2    | aux    | AUX_ADC, as in type 01                                  |
| 40     | 2    | crc    | CRC-16/CCITT-FALSE over bytes 2..39                      |

42 bytes, 3.646 ms on the wire at 115200 8N1 (36 % of the line at one every 10 ms).
"""
import numpy as np
from construct import Array, Int16sb, Int16ub, Int32sb, Struct, Terminated

from . import adis16350, adis16488
from .crcframe import crc_framed, encode, encode_rows
from .fast import packer_for, rows_packer

SYNC = b"\xa5\x5a"
TYPE_SAMPLE = 0x01
TYPE_MAGNETOMETER = 0x02
TYPE_WIDE_SAMPLE = 0x03
FRAME_SIZE = 30
MAG_FRAME_SIZE = 14
WIDE_FRAME_SIZE = 42
PERIOD_S = 0.01
SEQ_MODULO = 1 << 16

#: uT per LSB of a magnetometer word: HMC5883L gain 1090 LSB/gauss (1 gauss = 100 uT)
MAG_LSB_UT = 100.0 / 1090.0
#: the HMC5883L's data range and the value it reads on overflow (datasheet Rev. E, p. 15)
MAG_WORD_RANGE = (-2048, 2047)
MAG_OVERFLOW = -4096

Sample = Struct(
    "seq" / Int16ub,
    "words" / Array(11, Int16ub),
    Terminated,
)

Magnetometer = Struct(
    "seq" / Int16ub,
    "field" / Array(3, Int16sb),
    Terminated,
)

WideSample = Struct(
    "seq" / Int16ub,
    "supply" / Int16ub,
    "gyro" / Array(3, Int32sb),
    "accel" / Array(3, Int32sb),
    "temp" / Array(3, Int16ub),
    "aux" / Int16ub,
    Terminated,
)

#: the payload layout of each frame type
LAYOUTS = {TYPE_SAMPLE: Sample, TYPE_MAGNETOMETER: Magnetometer, TYPE_WIDE_SAMPLE: WideSample}

SinsFrame = crc_framed(SYNC, LAYOUTS)


_pack_sample = packer_for(Sample)
_pack_magnetometer = packer_for(Magnetometer)
_pack_wide_sample = packer_for(WideSample)
_rows_sample = rows_packer(Sample)
_rows_wide_sample = rows_packer(WideSample)


def build_sample(seq: int, words) -> bytes:
    """The 30-byte frame for one sample (fast path; equal to ``SinsFrame.build``)."""
    return encode(SYNC, TYPE_SAMPLE, _pack_sample(seq % SEQ_MODULO, *words))


def build_wide_sample(seq: int, supply: int, gyro, accel, temp, aux: int) -> bytes:
    """The 42-byte wide sample frame: *gyro*, *accel* three signed 32-bit words each, the
    housekeeping words as type 01 has them."""
    return encode(SYNC, TYPE_WIDE_SAMPLE, _pack_wide_sample(seq % SEQ_MODULO, supply, *gyro, *accel,
                                                            *temp, aux))


def build_samples(seq, words):
    """The sample frames of a block, one an (n, 30) uint8 row: *seq* (n,), *words* (n, 11)
    (= :func:`build_sample` of each row)."""
    return encode_rows(SYNC, TYPE_SAMPLE, _rows_sample(np.asarray(seq) % SEQ_MODULO, words))


def build_wide_samples(seq, words):
    """The wide sample frames of a block, (n, 42) uint8: *words* (n, 11) in type 01's order
    (supply, gyro x3, accel x3, temp x3, aux; = :func:`build_wide_sample` of each row)."""
    words = np.asarray(words)
    return encode_rows(SYNC, TYPE_WIDE_SAMPLE, _rows_wide_sample(
        np.asarray(seq) % SEQ_MODULO, words[:, 0], words[:, 1:4], words[:, 4:7], words[:, 7:10],
        words[:, 10]))


def to_sample(frame_type: int, fields: dict, gyro_range: int) -> adis16350.Sample:
    """Engineering units of a sample frame of either width (type 01 or 03); *gyro_range*
    (deg/s, the ADIS16350's SENS/AVG setting) scales type 01's gyro words only: the frame's
    type says which words it carries, so a reader needs no setting for the wide ones."""
    if frame_type == TYPE_WIDE_SAMPLE:
        return adis16488.to_sample(fields["supply"], fields["gyro"], fields["accel"],
                                   fields["temp"], fields["aux"])
    return adis16350.words_to_sample(fields["words"], gyro_range)


#: the frame types that carry a sample (the others ride in the same stream)
SAMPLE_TYPES = (TYPE_SAMPLE, TYPE_WIDE_SAMPLE)


def build_magnetometer(seq: int, field) -> bytes:
    """The 14-byte magnetometer frame: *field* the three signed words (x, y, z)."""
    return encode(SYNC, TYPE_MAGNETOMETER, _pack_magnetometer(seq % SEQ_MODULO, *field))


def field_ut(words) -> tuple[float, float, float] | None:
    """The field in uT of three magnetometer words; None if any axis overflowed."""
    if MAG_OVERFLOW in words:
        return None
    return tuple(w * MAG_LSB_UT for w in words)
