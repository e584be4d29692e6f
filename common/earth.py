"""The earth as both sides model it: the emulator's IMU senses its rotation, the host's
strapdown removes it (000 sect. 3.3)."""

EARTH_RATE = 7.2916e-5  # rad/s, sidereal rotation rate
