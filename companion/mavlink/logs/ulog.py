"""PX4 ULog logs (.ulg) read with pyulog, as MAVLink streams.

Topics used (instance 0 unless said; the ``timestamp`` of each is its boot time):

* ``sensor_combined`` -> HIGHRES_IMU, SCALED_IMU, with the latest
  ``vehicle_magnetometer`` (or the topic's own magnetometer in older logs) and
  ``vehicle_air_data`` (or the topic's own barometer) beside them;
* ``vehicle_attitude`` (quaternion) -> ATTITUDE, its rates the topic's own
  (older logs) or the latest ``vehicle_angular_velocity``;
* ``vehicle_gps_position`` or ``sensor_gps`` -> GPS_RAW_INT (instance 1: GPS2_RAW),
  every sample as logged, accuracies from ``eph``/``epv``/``s_variance_m_s``;
* the receiver's own ``jamming_state`` and ``spoofing_state`` of instance 0 (of
  ``sensor_gps`` when the log has them there, as PX4 streams them) -> GNSS_INTEGRITY,
  when they change and at most :data:`INTEGRITY_INTERVAL_US` apart otherwise, as PX4
  sends it (``id`` the device id's low byte; the states as logged: 0 unknown, 1 ok, 2
  mitigated -- "warning" / "spoofing indicated" before PX4 renamed them --, 3
  detected). Logs older than these fields (PX4 1.11's has ``jamming_indicator`` and
  ``noise_per_ms`` only: no MAVLink field carries them) give none;
* ``vehicle_global_position`` -> GLOBAL_POSITION_INT (velocity from the latest
  ``vehicle_local_position``, relative altitude against the first 3D-fix GNSS
  altitude, heading from the attitude);
* ``vehicle_status`` -> HEARTBEAT once a second (vehicle type, armed, mode).

The UTC offset is the median over the GNSS samples of their UTC time minus their
boot time (each jitters by a few milliseconds); a log without one
gets the fixed epoch of :data:`SYNTHETIC_EPOCH_US` plus boot time. A log pyulog
finds corrupt is read as far as it goes and counted ``bad_region``; a sample whose
values cannot be put in a message, ``bad_record``.
"""

from __future__ import annotations

import collections
import math
import statistics
from pathlib import Path
from typing import Any

import numpy as np

from companion.mavlink.logs.stream import (
    Event,
    ImuStreams,
    LogStream,
    heartbeat_events,
    to_int,
    wrap_cdeg,
)
from companion.nav.rotations import quat_to_euler

MAV_AUTOPILOT_PX4 = 12
INTEGRITY_INTERVAL_US = 1_000_000
"""An unchanged GNSS_INTEGRITY is repeated this often (PX4's stream: 1 Hz)."""
SYNTHETIC_EPOCH_US = 1_500_000_000_000_000
"""UNIX time given to boot time 0 of a log without GNSS time (2017-07-14T02:40:00Z)."""
ARMING_STATE_ARMED = 2
_PX4_MODE: dict[int, tuple[int, int]] = {
    0: (1, 0),  # manual
    1: (2, 0),  # altitude
    2: (3, 0),  # position
    3: (4, 4),  # auto mission
    4: (4, 3),  # auto loiter
    5: (4, 5),  # auto RTL
    10: (5, 0),  # acro
    12: (4, 6),  # descend
    14: (6, 0),  # offboard
    15: (7, 0),  # stabilised
    17: (4, 2),  # takeoff
    18: (4, 6),  # land
    19: (4, 8),  # follow target
    20: (4, 9),  # precision land
    22: (4, 10),  # VTOL takeoff
}
"""vehicle_status.nav_state -> PX4's (main mode, sub mode) of HEARTBEAT.custom_mode."""
TOPICS = [
    "sensor_combined", "vehicle_magnetometer", "vehicle_air_data", "vehicle_attitude",
    "vehicle_angular_velocity", "vehicle_gps_position", "sensor_gps",
    "vehicle_global_position", "vehicle_local_position", "vehicle_status",
]  # fmt: skip


WHAT = "a PX4 ULog (.ulg)"


class UlogError(Exception):
    """The file cannot be read as a ULog at all."""


def _mav_type(row: dict[str, Any]) -> int:
    if row.get("is_vtol"):
        return 22
    vehicle_type = row.get("vehicle_type")
    if vehicle_type is None:
        return 2 if row.get("is_rotary_wing") else 1
    return {1: 2, 2: 1, 3: 10, 4: 7}.get(int(vehicle_type), 0)


def read_ulog(path: Path | str, light_ids: frozenset[int] | None = None) -> LogStream:
    """The MAVLink streams of a ULog (see the module's docstring).

    Raises
    ------
    UlogError
        When pyulog cannot read the file at all.
    """
    from pyulog import ULog

    stats: collections.Counter[str] = collections.Counter()
    try:
        ulog = ULog(str(path), TOPICS, disable_str_exceptions=True)
    except (OSError, ValueError, IndexError, KeyError, TypeError, EOFError) as exc:
        raise UlogError(f"{path}: not a readable ULog: {exc}") from exc
    if ulog.file_corruption:
        stats["bad_region"] += 1
    topics: dict[str, dict[str, np.ndarray]] = {}
    for data in ulog.data_list:
        name = data.name
        if data.multi_id != 0 and name not in ("vehicle_gps_position", "sensor_gps"):
            continue
        key = name if data.multi_id == 0 else f"{name}#{data.multi_id}"
        topics[key] = data.data
    events, offset_us = _events(topics, stats)
    if light_ids is None:
        return LogStream(events, offset_us, stats, stats_prefix="ulog_", what=WHAT)
    return LogStream(events, offset_us, stats, light_ids, stats_prefix="ulog_", what=WHAT)


def _rows(topics: dict[str, dict[str, np.ndarray]]) -> list[tuple[int, int, str, int]]:
    """(timestamp µs, topic rank, topic, row index) of every sample, in time order."""
    rows: list[tuple[int, int, str, int]] = []
    for rank, key in enumerate(sorted(topics, key=_rank)):
        ts = topics[key]["timestamp"]
        rows += [(int(t), rank, key, i) for i, t in enumerate(ts.tolist())]
    rows.sort()
    return rows


def _rank(key: str) -> int:
    base = key.split("#")[0]
    return TOPICS.index(base) if base in TOPICS else len(TOPICS)


def _events(
    topics: dict[str, dict[str, np.ndarray]], stats: collections.Counter[str]
) -> tuple[list[Event], int]:
    events: list[Event] = []
    imu = ImuStreams()
    status: list[tuple[int, bool, int]] = []
    mav_type = 0
    gyro_radps = (0.0, 0.0, 0.0)
    vel_ned = (0.0, 0.0, 0.0)
    yaw_rad: float | None = None
    first_fix_alt_m: float | None = None
    utc_offsets: list[int] = []
    integrity_key = next(
        (k for k in ("sensor_gps", "vehicle_gps_position") if "jamming_state" in topics.get(k, {})),
        None,
    )
    last_integrity: tuple[int, tuple[int, int]] | None = None
    cols: dict[str, dict[str, list[Any]]] = {
        key: {f: v.tolist() for f, v in data.items()} for key, data in topics.items()
    }

    def get(key: str, field: str, i: int, default: Any = None) -> Any:
        col = cols[key].get(field)
        return default if col is None else col[i]

    for order, (t_us, _, key, i) in enumerate(_rows(topics)):
        name = key.split("#")[0]
        try:
            if name == "sensor_combined":
                c = cols[key]
                if "magnetometer_ga[0]" in c:
                    imu.mag_gauss = tuple(c[f"magnetometer_ga[{k}]"][i] for k in range(3))  # type: ignore[assignment]
                if "baro_alt_meter" in c:
                    imu.baro = (0.0, c["baro_alt_meter"][i], c["baro_temp_celcius"][i])
                acc = tuple(float(c[f"accelerometer_m_s2[{k}]"][i]) for k in range(3))
                gyro = tuple(float(c[f"gyro_rad[{k}]"][i]) for k in range(3))
                events += imu.events(t_us, order, acc, gyro, None)  # type: ignore[arg-type]
            elif name == "vehicle_magnetometer":
                imu.mag_gauss = tuple(get(key, f"magnetometer_ga[{k}]", i) for k in range(3))  # type: ignore[assignment]
            elif name == "vehicle_air_data":
                imu.baro = (
                    get(key, "baro_pressure_pa", i, 0.0) / 100.0,
                    get(key, "baro_alt_meter", i),
                    get(key, "baro_temp_celcius", i, 0.0),
                )
            elif name == "vehicle_angular_velocity":
                gyro_radps = tuple(get(key, f"xyz[{k}]", i) for k in range(3))  # type: ignore[assignment]
            elif name == "vehicle_attitude":
                q = [get(key, f"q[{k}]", i) for k in range(4)]
                n = math.sqrt(sum(v * v for v in q))
                if not (math.isfinite(n) and n > 0.0):
                    raise ValueError("quaternion")
                roll, pitch, yaw = quat_to_euler([v / n for v in q])
                yaw_rad = yaw
                rates = gyro_radps
                if "rollspeed" in cols[key]:
                    rates = (
                        get(key, "rollspeed", i),
                        get(key, "pitchspeed", i),
                        get(key, "yawspeed", i),
                    )
                args = [to_int(t_us / 1000.0), roll, pitch, yaw, *rates]
                events.append(Event(t_us, order, "attitude", args))
            elif name in ("vehicle_gps_position", "sensor_gps"):
                ev = _gnss(key, i, t_us, order, cols[key])
                if ev is None:
                    continue
                utc = get(key, "time_utc_usec", i, 0)
                if utc > 0:
                    utc_offsets.append(int(utc) - t_us)
                if ev.args[1] >= 3 and first_fix_alt_m is None:
                    first_fix_alt_m = ev.args[4] / 1000.0
                events.append(ev)
                if key == integrity_key:
                    states = (
                        int(get(key, "jamming_state", i)),
                        int(get(key, "spoofing_state", i, 0)),
                    )
                    if (
                        last_integrity is None
                        or last_integrity[1] != states
                        or t_us - last_integrity[0] >= INTEGRITY_INTERVAL_US
                    ):
                        last_integrity = (t_us, states)
                        device = int(get(key, "device_id", i, 0)) & 0xFF
                        auth = int(get(key, "authentication_state", i, 0))
                        events.append(
                            Event(
                                t_us, order, "gnss_integrity", _integrity_args(device, auth, states)
                            )
                        )
            elif name == "vehicle_local_position":
                vel_ned = (get(key, "vx", i), get(key, "vy", i), get(key, "vz", i))
            elif name == "vehicle_global_position":
                alt = get(key, "alt", i)
                rel = 0 if first_fix_alt_m is None else to_int(alt - first_fix_alt_m, 1e3)
                events.append(
                    Event(
                        t_us, order, "global_position_int",
                        [
                            to_int(t_us / 1000.0), to_int(get(key, "lat", i), 1e7),
                            to_int(get(key, "lon", i), 1e7), to_int(alt, 1e3), rel,
                            *(to_int(v, 100.0) for v in vel_ned),
                            65535 if yaw_rad is None else wrap_cdeg(math.degrees(yaw_rad)),
                        ],
                    )
                )  # fmt: skip
            elif name == "vehicle_status":
                row = {f: v[i] for f, v in cols[key].items()}
                mav_type = _mav_type(row)
                main, sub = _PX4_MODE.get(int(row.get("nav_state", 0)), (0, 0))
                armed = int(row.get("arming_state", 0)) == ARMING_STATE_ARMED
                status.append((t_us, armed, (main << 16) | (sub << 24)))
        except (ValueError, TypeError, OverflowError, KeyError):
            stats["bad_record"] += 1
    # the median of the samples' UTC minus boot time (each jitters by a few ms)
    offset_us = int(statistics.median(utc_offsets)) if utc_offsets else SYNTHETIC_EPOCH_US
    if not events:
        return events, offset_us
    first = min(e.t_us for e in events)
    last = max(e.t_us for e in events)
    events += heartbeat_events(first, last, status, mav_type, MAV_AUTOPILOT_PX4)
    return events, offset_us


def _integrity_args(device: int, authentication: int, states: tuple[int, int]) -> list[int]:
    """GNSS_INTEGRITY's arguments: the receiver's states, nothing else known."""
    jamming, spoofing = states
    return [device, 0, authentication, jamming, spoofing, 0, 65535, 65535, 255, 255, 255, 255]


def _gnss(key: str, i: int, t_us: int, order: int, c: dict[str, list[Any]]) -> Event | None:
    """GPS_RAW_INT (GPS2_RAW for instance 1) of one GNSS sample (``c``: the topic's columns)."""

    def get(field: str, default: Any = None) -> Any:
        col = c.get(field)
        return default if col is None else col[i]

    if "latitude_deg" in c:
        lat = to_int(get("latitude_deg"), 1e7)
        lon = to_int(get("longitude_deg"), 1e7)
        alt = to_int(get("altitude_msl_m"), 1e3)
        alt_ell = to_int(get("altitude_ellipsoid_m", 0.0), 1e3)
    else:
        lat, lon = int(get("lat")), int(get("lon"))
        alt, alt_ell = int(get("alt")), int(get("alt_ellipsoid", 0))
    cog = get("cog_rad", float("nan"))
    args = [
        t_us, int(get("fix_type")), lat, lon, alt,
        to_int(get("hdop", 655.35), 100.0), to_int(get("vdop", 655.35), 100.0),
        to_int(get("vel_m_s"), 100.0),
        wrap_cdeg(math.degrees(cog)) if math.isfinite(cog) else 65535,
        int(get("satellites_used", 255)),
    ]  # fmt: skip
    h_acc = to_int(get("eph"), 1e3)
    v_acc = to_int(get("epv"), 1e3)
    vel_acc = to_int(get("s_variance_m_s", 0.0), 1e3)
    if key.endswith("#1"):
        return Event(t_us, order, "gps2_raw", [*args, 0, 0, 0, alt_ell, h_acc, v_acc, vel_acc, 0])
    if "#" in key:
        return None
    return Event(t_us, order, "gps_raw_int", [*args, alt_ell, h_acc, v_acc, vel_acc, 0, 0])
