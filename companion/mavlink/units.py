"""MAVLink field scalings: the one place they are written down.

Every integer scaling MAVLink uses (1e7 degrees, mm, cm/s, mG, mrad/s,
centidegrees, "unknown" sentinels) lives here, and is applied only in
:mod:`companion.mavlink` (decode, encode, and readback of what we published)
and the simulator's autopilot writer (which must speak the autopilot's
dialect). The core never sees a MAVLink unit. Message ids and enum values are
in :mod:`companion.mavlink.ids`.
"""

from __future__ import annotations

import math

STANDARD_GRAVITY_MPS2 = 9.80665
"""g0 as MAVLink's milli-g fields use it (RAW_IMU / SCALED_IMU), m/s^2."""

DEGE7_PER_RAD = 1e7 * 180.0 / math.pi
"""lat/lon integers are degrees * 1e7."""

MM_PER_M = 1000.0
CM_PER_M = 100.0
MG_PER_MPS2 = 1000.0 / STANDARD_GRAVITY_MPS2
"""RAW_IMU / SCALED_IMU specific force is in milli-g."""
MRAD_PER_RAD = 1000.0
CDEG_PER_RAD = 100.0 * 180.0 / math.pi
"""Course over ground, VFR heading (deg), GLOBAL_POSITION_INT.hdg are centidegrees."""
DOP_SCALE = 100.0
"""eph/epv carry HDOP/VDOP * 100."""
US_PER_S = 1e6
MS_PER_S = 1e3

UINT16_UNKNOWN = 65535
"""MAVLink's 'unknown' for uint16 fields such as eph, epv, vel, cog, hdg."""
UINT8_UNKNOWN = 255
"""satellites_visible unknown."""

EPOCH_USEC_THRESHOLD = 1_000_000_000_000_000
"""A time_usec above this (about 31.7 years) is UNIX epoch time, not time since boot
(MAVLink: 'the receiving end can infer timestamp format by checking the magnitude')."""
