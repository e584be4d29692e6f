"""The noise the host's reads of the ADIS16350 carry: its filters' default IMU figures.

The board reads the registers every 10 ms (protocols.sins.PERIOD_S), one sample of the
819.2 SPS stream after the power-up 4-tap Bartlett filter. Its 7 taps span 8.5 ms, less than
a read period, so the filter passes noise above the reads' 50 Hz Nyquist and the reads alias
it: their white noise is the sensor's times read_white_factor = 1.19 (exact, aliasing
included), ARW 2.52 deg/sqrt(h) and VRW 0.91 m/s/sqrt(h) from the datasheet's per-sample
densities, not the sensor's 2.12 and 0.77 nor the datasheet's stated 4.2 and 2.0
(docs/emulator-models.md 3.2). The bias's Allan floor, at millihertz, passes unchanged.
"""
from __future__ import annotations

from navtwin.protocols import adis16350 as adis, sins

#: white noise of the reads / the sensor's, at the power-up sample rate and taps
READ_WHITE_FACTOR = adis.read_white_factor(adis.POWER_UP_FILTER_TAPS, adis.POWER_UP_SAMPLE_RATE_HZ,
                                           sins.PERIOD_S)
#: deg/sqrt(h), the gyro angle random walk of the reads (to 2 decimals, as a setting is written)
ARW_DEG_RT_HR = round(adis.SENSOR_ARW_DEG_RT_HR * READ_WHITE_FACTOR, 2)
#: m/s/sqrt(h), the accelerometer velocity random walk of the reads
VRW_M_S_RT_HR = round(adis.SENSOR_VRW_M_S_RT_HR * READ_WHITE_FACTOR, 2)
#: deg/s, the gyro bias's Allan floor (in-run bias stability)
GYRO_BIAS_INSTABILITY_DPS = adis.GYRO_BIAS_INSTABILITY_DPS
