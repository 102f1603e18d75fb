"""MAVLink numbers the service uses, each written once.

Frame layout, message ids, the values of the MAVLink enums we send or test
(MAV_CMD, MAV_RESULT, MAV_STATE, MAV_AUTOPILOT, MAV_TYPE, MAV_COMP_ID,
MAV_DATA_STREAM and flags), text field lengths, and the one convention of our
own messages (the ``CMP`` prefix of an alert's STATUSTEXT). Field scalings are
in :mod:`companion.mavlink.units`; MAV_SEVERITY is :class:`companion.types.Severity`
(the core's alert type).

The names are pymavlink's, and the values those of its generated dialects
(common.xml, ardupilotmega.xml, development.xml): ``tests/mavlink/test_ids.py``
checks every name a dialect defines against it. They are written out rather
than imported so that the decoder and the tools that only read these numbers
do not load a dialect module.

References
----------
MAVLink common message set: https://mavlink.io/en/messages/common.html;
serialization: https://mavlink.io/en/guide/serialization.html
"""

from __future__ import annotations

# --------------------------------------------------------------------------- frame layout

STX_V1 = 0xFE
"""Start byte of a MAVLink 1 frame."""
STX_V2 = 0xFD
"""Start byte of a MAVLink 2 frame."""
HEADER_LEN_V1 = 6
"""STX, length, sequence, system, component, message id."""
HEADER_LEN_V2 = 10
"""STX, length, incompat and compat flags, sequence, system, component, 24-bit id."""
CRC_LEN = 2
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
"""MAVLink 2 incompatibility flag: the frame carries a signature."""
MAVLINK_VERSION = 3
"""HEARTBEAT.mavlink_version."""

# --------------------------------------------------------------------------- message ids

MAVLINK_MSG_ID_HEARTBEAT = 0
MAVLINK_MSG_ID_SYSTEM_TIME = 2
MAVLINK_MSG_ID_GPS_RAW_INT = 24
MAVLINK_MSG_ID_SCALED_IMU = 26
MAVLINK_MSG_ID_RAW_IMU = 27
MAVLINK_MSG_ID_SCALED_PRESSURE = 29
MAVLINK_MSG_ID_ATTITUDE = 30
MAVLINK_MSG_ID_ATTITUDE_QUATERNION = 31
MAVLINK_MSG_ID_GLOBAL_POSITION_INT = 33
MAVLINK_MSG_ID_VFR_HUD = 74
MAVLINK_MSG_ID_COMMAND_INT = 75
MAVLINK_MSG_ID_COMMAND_LONG = 76
MAVLINK_MSG_ID_HIGHRES_IMU = 105
MAVLINK_MSG_ID_SCALED_IMU2 = 116
MAVLINK_MSG_ID_GPS2_RAW = 124
MAVLINK_MSG_ID_GPS_RTK = 127
MAVLINK_MSG_ID_GPS2_RTK = 128
MAVLINK_MSG_ID_SCALED_PRESSURE2 = 137
MAVLINK_MSG_ID_SCALED_IMU3 = 129
MAVLINK_MSG_ID_EXTENDED_SYS_STATE = 245
MAVLINK_MSG_ID_GNSS_INTEGRITY = 441
"""Development set (PX4 sends it; ArduPilot's dialect does not carry it)."""

# --------------------------------------------------------------------------- components

MAV_COMP_ID_AUTOPILOT1 = 1
MAV_COMP_ID_ONBOARD_COMPUTER = 191
"""Our component: every message the service sends comes from it."""

# --------------------------------------------------------------------------- HEARTBEAT

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_INVALID = 8
"""Not an autopilot (ground stations, companions such as this service)."""
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4
MAV_STATE_CRITICAL = 5
MAV_STATE_FLIGHT_TERMINATION = 8
"""The last MAV_STATE value."""

# --------------------------------------------------------------------------- commands

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_USER_1 = 31010
"""The heading command (COMMAND_LONG or COMMAND_INT; param1 1 confirm, 0 refuse, 2 undo)."""
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_TEMPORARILY_REJECTED = 1
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3
MAV_RESULT_FAILED = 4

# --------------------------------------------------------------------------- data streams

MAV_DATA_STREAM_RAW_SENSORS = 1
MAV_DATA_STREAM_EXTENDED_STATUS = 2
MAV_DATA_STREAM_POSITION = 6
MAV_DATA_STREAM_EXTRA1 = 10
MAV_DATA_STREAM_EXTRA2 = 11
MAV_DATA_STREAM_EXTRA3 = 12

# --------------------------------------------------------------------------- output fields

GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY = 64
GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY = 128
GLOBAL_POSITION_SRC_ESTIMATOR = 6
GLOBAL_POSITION_UNHEALTHY = 1
GLOBAL_POSITION_PRIMARY = 2
GPS_RAIM_STATE_OK = 2
GPS_RAIM_STATE_FAILED = 3
GPS_JAMMING_STATE_UNKNOWN = 0
GPS_JAMMING_STATE_NOT_JAMMED = 1
GPS_JAMMING_STATE_MITIGATED = 2
GPS_JAMMING_STATE_DETECTED = 3
GPS_SPOOFING_STATE_UNKNOWN = 0
GPS_SPOOFING_STATE_NOT_SPOOFED = 1
GPS_SPOOFING_STATE_MITIGATED = 2
GPS_SPOOFING_STATE_DETECTED = 3

STATUSTEXT_MAX_CHARS = 50
"""STATUSTEXT.text is char[50]; a shorter chunk ends a multi-chunk text."""
STATUSTEXT_MAX_CHUNKS = 4
"""Chunks of one alert at most (200 characters); the rest is cut."""
NAMED_VALUE_MAX_CHARS = 10
"""NAMED_VALUE_FLOAT.name is char[10]."""

ALERT_PREFIX = "CMP "
"""Our alerts' STATUSTEXT is ``CMP <CODE> <text>`` (:class:`companion.types.AlertCode`)."""
