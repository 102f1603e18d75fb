"""The simulated autopilot: MAVLink messages of each flavour and the typed samples they decode to.

Each stream returns, per message, the ``pymavlink`` message and the typed
sample a decoder makes of it, built from the message's own (quantised) fields
with the scalings of :mod:`companion.mavlink.units`. Scalings are written
nowhere else.

Decoding conventions the samples follow (what :mod:`companion.mavlink.decode`
is expected to do):

* RAW_IMU, HIGHRES_IMU: ``t_s = time_usec / 1e6``; SCALED_IMU2, ATTITUDE,
  ATTITUDE_QUATERNION, GLOBAL_POSITION_INT: ``t_s = time_boot_ms / 1e3``.
* ``imu_id``: RAW_IMU / HIGHRES_IMU their ``id`` field (0); SCALED_IMU2 is IMU 1.
* GPS_RAW_INT ``time_usec``: ArduPilot stamps UNIX-epoch microseconds of the
  fix, PX4 time since boot; ``t_s`` is the fix's boot time either way (the
  epoch offset is given by SYSTEM_TIME, sent at 1 Hz by both flavours). ArduPilot's
  stamp is the receiver's own time: a meaconed receiver's clock is late by the replay's
  delay, and so is its ``t_s`` (the decoder also rejects the stamps that step back,
  ``time_backwards``, which the samples here do not model).
* GNSS_INTEGRITY (development dialect, ``Scenario.gnss_integrity_relay``): a
  :class:`GnssSignalReport` with ``source = "autopilot"``, the states mapped from
  GPS_JAMMING_STATE / GPS_SPOOFING_STATE (0 unknown, 1 clean, 2 mitigated, 3 detected)
  and the latest boot-clock ``t_s`` (the message carries no time).
* GPS_RAW_INT/GPS2_RAW: ``vel_ne_mps = vel/100 * (cos cog, sin cog)``,
  ``h_acc``, ``v_acc``, ``vel_acc`` in mm (0 = unknown -> None), eph/epv / 100
  (65535 -> None), ``dgps_age_s`` from GPS2_RAW's ``dgps_age`` (ms), None for
  GPS_RAW_INT.
* HEARTBEAT, VFR_HUD, EXTENDED_SYS_STATE, GPS_RTK carry no usable time: their
  ``t_s`` is the largest boot-clock ``t_s`` of the IMU, attitude, GNSS and
  GLOBAL_POSITION_INT messages received before them (SYSTEM_TIME does not count).
  GPS_RTK's ``time_last_baseline_ms`` is the fix time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from companion.mavlink import units
from companion.nav.rotations import quat_to_euler
from companion.types import (
    AttitudeSample,
    AutopilotSolution,
    BaroSample,
    FixType,
    FloatArray,
    GnssFix,
    GnssSignalReport,
    HeartbeatSample,
    ImuSample,
    InterferenceState,
    LandedState,
    LandedStateSample,
    RtkStatus,
    Sample,
    VfrHudSample,
)

MakeFn = Callable[[int, float, float | None], tuple[Any, Sample | None, float | None]]
"""make(i, t_rx_s, last_known_t_s) -> (message, sample or None, t_s it establishes or None).

``last_known_t_s`` is None until a timed message has been received: untimed
messages then give no sample (a decoder has no clock for them yet)."""

_RAD_PER_DEGE7 = 1.0 / units.DEGE7_PER_RAD
_RAD_PER_CDEG = 1.0 / units.CDEG_PER_RAD
GPS_EPOCH_UNIX_S = 315_964_800
GPS_LEAP_S = 18
MAG_NED_MGAUSS = np.array([180.0, 15.0, 460.0])
"""Earth's field near the default airfield, mGauss (for the IMU's mag fields)."""

LANDED_BY_PHASE = {
    "parked": LandedState.ON_GROUND,
    "taxi": LandedState.ON_GROUND,
    "lineup": LandedState.ON_GROUND,
    "takeoff_roll": LandedState.ON_GROUND,
    "landing_roll": LandedState.ON_GROUND,
    "rotation": LandedState.TAKEOFF,
    "climb": LandedState.TAKEOFF,
    "takeoff": LandedState.TAKEOFF,
    "cruise": LandedState.IN_AIR,
    "hover": LandedState.IN_AIR,
    "transition": LandedState.IN_AIR,
    "descent": LandedState.LANDING,
    "flare": LandedState.LANDING,
}
THROTTLE_BY_PHASE = {
    "parked": 0,
    "taxi": 15,
    "lineup": 10,
    "takeoff_roll": 90,
    "rotation": 90,
    "climb": 85,
    "takeoff": 70,
    "cruise": 55,
    "hover": 50,
    "transition": 55,
    "descent": 30,
    "flare": 10,
    "landing_roll": 0,
}


@dataclass(frozen=True, slots=True)
class Stream:
    """One message stream: emission times (autopilot boot s) and how to make message i."""

    name: str
    emit_s: FloatArray
    make: MakeFn


def _i(x: float, lo: int, hi: int) -> int:
    """Round to int and clip to a field's range."""
    return int(min(max(round(x), lo), hi))


def _f32(x: float) -> float:
    return float(np.float32(x))


# --------------------------------------------------------------------------- IMU


def imu_stream(
    message: str,
    t_s: FloatArray,
    acc_b_mps2: FloatArray,
    gyro_b_radps: FloatArray,
    mat_nb: FloatArray,
    alt_msl_m: FloatArray,
) -> Stream:
    """RAW_IMU / SCALED_IMU2 / SCALED_IMU3 (mG, mrad/s integers) or HIGHRES_IMU (float32 SI)."""
    mag_b = np.einsum("nji,j->ni", mat_nb, MAG_NED_MGAUSS)
    emit = t_s + 0.001
    if message in ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3"):
        acc_i = np.clip(np.rint(acc_b_mps2 * units.MG_PER_MPS2), -32768, 32767).astype(int)
        gyr_i = np.clip(np.rint(gyro_b_radps * units.MRAD_PER_RAD), -32768, 32767).astype(int)
        mag_i = np.clip(np.rint(mag_b), -32768, 32767).astype(int)
        acc_dec = acc_i * (1.0 / units.MG_PER_MPS2)
        gyr_dec = gyr_i * (1.0 / units.MRAD_PER_RAD)
        raw = message == "RAW_IMU"
        stamp = (
            np.rint(t_s * units.US_PER_S).astype(np.int64)
            if raw
            else np.rint(t_s * units.MS_PER_S).astype(np.int64)
        )
        acc_l, gyr_l, mag_l, st_l = acc_i.tolist(), gyr_i.tolist(), mag_i.tolist(), stamp.tolist()
        imu_id = {"RAW_IMU": 0, "SCALED_IMU2": 1, "SCALED_IMU3": 2}[message]
        scaled_cls = (
            mav.MAVLink_scaled_imu3_message
            if message == "SCALED_IMU3"
            else mav.MAVLink_scaled_imu2_message
        )

        def make_int(
            i: int, t_rx: float, _last: float | None
        ) -> tuple[Any, Sample | None, float | None]:
            a, g, m = acc_l[i], gyr_l[i], mag_l[i]
            if raw:
                msg = mav.MAVLink_raw_imu_message(st_l[i], *a, *g, *m, 0, 4500)
                t = st_l[i] / units.US_PER_S
            else:
                msg = scaled_cls(st_l[i], *a, *g, *m, 4500)
                t = st_l[i] / units.MS_PER_S
            smp = ImuSample(t, t_rx, acc_dec[i].copy(), gyr_dec[i].copy(), imu_id, message)
            return msg, smp, t

        return Stream(message, emit, make_int)
    if message != "HIGHRES_IMU":
        raise ValueError(f"unknown IMU message {message!r}")
    acc32 = acc_b_mps2.astype(np.float32)
    gyr32 = gyro_b_radps.astype(np.float32)
    mag32 = (mag_b / 1000.0).astype(np.float32)
    p_hpa = (1013.25 * (1.0 - 2.25577e-5 * alt_msl_m) ** 5.25588).astype(np.float32)
    stamp = np.rint(t_s * units.US_PER_S).astype(np.int64).tolist()
    acc_dec = acc32.astype(float)
    gyr_dec = gyr32.astype(float)
    acc_l, gyr_l, mag_l = acc32.tolist(), gyr32.tolist(), mag32.tolist()
    p_l, alt_l = p_hpa.tolist(), alt_msl_m.astype(np.float32).tolist()

    def make_hr(
        i: int, t_rx: float, _last: float | None
    ) -> tuple[Any, Sample | None, float | None]:
        msg = mav.MAVLink_highres_imu_message(
            stamp[i], *acc_l[i], *gyr_l[i], *mag_l[i], p_l[i], 0.0, alt_l[i], 25.0, 0x1FFF, 0
        )
        t = stamp[i] / units.US_PER_S
        return msg, ImuSample(t, t_rx, acc_dec[i].copy(), gyr_dec[i].copy(), 0, message), t

    return Stream(message, emit, make_hr)


# --------------------------------------------------------------------------- attitude


def euler_to_quat_batch(euler_rad: FloatArray) -> FloatArray:
    """Body-to-NED quaternions (w, x, y, z) from ZYX Euler angles, (N, 3) -> (N, 4)."""
    hr, hp, hy = euler_rad[:, 0] / 2, euler_rad[:, 1] / 2, euler_rad[:, 2] / 2
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    return np.column_stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def attitude_stream(
    quaternion: bool, t_s: FloatArray, euler_rad: FloatArray, rate_b_radps: FloatArray
) -> Stream:
    """ATTITUDE (ArduPilot) or ATTITUDE_QUATERNION (PX4), float32 fields, time_boot_ms."""
    ms = np.rint(t_s * units.MS_PER_S).astype(np.int64).tolist()
    rates32 = rate_b_radps.astype(np.float32)
    rates_l = rates32.tolist()
    emit = t_s + 0.002
    if quaternion:
        q32 = euler_to_quat_batch(euler_rad).astype(np.float32)
        q_l = q32.tolist()

        def make_q(
            i: int, t_rx: float, _last: float | None
        ) -> tuple[Any, Sample | None, float | None]:
            msg = mav.MAVLink_attitude_quaternion_message(ms[i], *q_l[i], *rates_l[i], [0.0] * 4)
            q = np.asarray(q_l[i], dtype=float)
            r, p, y = quat_to_euler(q / math.sqrt(float(q @ q)))
            t = ms[i] / units.MS_PER_S
            return msg, AttitudeSample(t, t_rx, r, p, y, rates32[i].astype(float)), t

        return Stream("ATTITUDE_QUATERNION", emit, make_q)
    wrapped = euler_rad.copy()
    wrapped[:, 2] = (wrapped[:, 2] + np.pi) % (2 * np.pi) - np.pi
    e32 = wrapped.astype(np.float32)
    e_l = e32.tolist()

    def make_e(i: int, t_rx: float, _last: float | None) -> tuple[Any, Sample | None, float | None]:
        msg = mav.MAVLink_attitude_message(ms[i], *e_l[i], *rates_l[i])
        t = ms[i] / units.MS_PER_S
        r, p, y = e_l[i]
        return msg, AttitudeSample(t, t_rx, r, p, y, rates32[i].astype(float)), t

    return Stream("ATTITUDE", emit, make_e)


# --------------------------------------------------------------------------- GNSS


@dataclass(frozen=True, slots=True)
class GnssReport:
    """What a receiver reports at one fix (SI; before MAVLink scaling)."""

    t_fix_s: float
    fix_type: FixType
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    alt_hae_m: float
    vel_ne_mps: FloatArray
    h_acc_m: float
    v_acc_m: float
    vel_acc_mps: float
    hdop: float
    vdop: float
    satellites: int
    keep_coords: bool = False
    """Write the coordinates even without a fix (a receiver's garbage during no-fix)."""
    clock_offset_s: float = 0.0
    """The receiver's clock minus the true time (meaconing: minus the delay), s: it shows
    where the autopilot stamps the receiver's time (ArduPilot's ``time_usec``)."""


def gnss_stream(
    receiver_id: int,
    ardupilot: bool,
    epoch0_s: float,
    reports: list[GnssReport],
    latency_s: float,
) -> Stream:
    """GPS_RAW_INT (receiver 0) or GPS2_RAW (receiver 1) from the receiver's reports."""
    emit = np.array([r.t_fix_s + latency_s for r in reports])
    name = "GPS_RAW_INT" if receiver_id == 0 else "GPS2_RAW"

    def make(i: int, t_rx: float, _last: float | None) -> tuple[Any, Sample | None, float | None]:
        r = reports[i]
        boot_us = round(r.t_fix_s * units.US_PER_S)
        clock_us = round(r.clock_offset_s * units.US_PER_S)
        epoch_us = round(epoch0_s * units.US_PER_S) + boot_us + clock_us
        time_usec = epoch_us if ardupilot else boot_us
        has_fix = r.fix_type >= FixType.FIX_2D
        coords = has_fix or r.keep_coords
        lat = _i(r.lat_rad * units.DEGE7_PER_RAD, -(2**31), 2**31 - 1) if coords else 0
        lon = _i(r.lon_rad * units.DEGE7_PER_RAD, -(2**31), 2**31 - 1) if coords else 0
        alt = _i(r.alt_msl_m * units.MM_PER_M, -(2**31), 2**31 - 1) if coords else 0
        alt_e = _i(r.alt_hae_m * units.MM_PER_M, -(2**31), 2**31 - 1) if has_fix else 0
        gs = float(np.hypot(r.vel_ne_mps[0], r.vel_ne_mps[1]))
        vel = _i(gs * units.CM_PER_M, 0, units.UINT16_UNKNOWN - 1)
        cog_rad = math.atan2(r.vel_ne_mps[1], r.vel_ne_mps[0]) % (2.0 * math.pi)
        cog = _i(cog_rad * units.CDEG_PER_RAD, 0, 36000) % 36000
        if not has_fix:
            vel, cog = units.UINT16_UNKNOWN, units.UINT16_UNKNOWN
        eph = _i(r.hdop * units.DOP_SCALE, 0, units.UINT16_UNKNOWN) if has_fix else 65535
        epv = _i(r.vdop * units.DOP_SCALE, 0, units.UINT16_UNKNOWN) if has_fix else 65535
        h_acc = _i(r.h_acc_m * units.MM_PER_M, 0, 2**32 - 1) if has_fix else 0
        v_acc = _i(r.v_acc_m * units.MM_PER_M, 0, 2**32 - 1) if has_fix else 0
        vel_acc = _i(r.vel_acc_mps * units.MM_PER_M, 0, 2**32 - 1) if has_fix else 0
        sats = int(r.satellites)
        if receiver_id == 0:
            msg = mav.MAVLink_gps_raw_int_message(
                time_usec, int(r.fix_type), lat, lon, alt, eph, epv, vel, cog, sats,
                alt_e, h_acc, v_acc, vel_acc, 0, 0,
            )  # fmt: skip
            dgps_age = None
        else:
            age_ms = 1000 if r.fix_type >= FixType.DGPS else 0
            msg = mav.MAVLink_gps2_raw_message(
                time_usec, int(r.fix_type), lat, lon, alt, eph, epv, vel, cog, sats,
                4 if age_ms else 0, age_ms, 0, alt_e, h_acc, v_acc, vel_acc, 0,
            )  # fmt: skip
            dgps_age = age_ms / units.MS_PER_S
        t = (boot_us + clock_us if ardupilot else boot_us) / units.US_PER_S
        course = None if cog == units.UINT16_UNKNOWN else cog * _RAD_PER_CDEG
        gs_dec = 0.0 if vel == units.UINT16_UNKNOWN else vel / units.CM_PER_M
        vel_ne = (
            None
            if course is None
            else np.array([gs_dec * math.cos(course), gs_dec * math.sin(course)])
        )
        smp = GnssFix(
            t_s=t,
            t_rx_s=t_rx,
            receiver_id=receiver_id,
            fix_type=FixType(int(r.fix_type)),
            lat_rad=lat * _RAD_PER_DEGE7,
            lon_rad=lon * _RAD_PER_DEGE7,
            alt_msl_m=alt / units.MM_PER_M,
            alt_hae_m=alt_e / units.MM_PER_M if has_fix else None,
            vel_ne_mps=vel_ne,
            ground_speed_mps=gs_dec,
            course_rad=course,
            h_acc_m=h_acc / units.MM_PER_M if h_acc else None,
            v_acc_m=v_acc / units.MM_PER_M if v_acc else None,
            vel_acc_mps=vel_acc / units.MM_PER_M if vel_acc else None,
            hdop=None if eph == units.UINT16_UNKNOWN else eph / units.DOP_SCALE,
            vdop=None if epv == units.UINT16_UNKNOWN else epv / units.DOP_SCALE,
            satellites=None if sats == units.UINT8_UNKNOWN else sats,
            dgps_age_s=dgps_age,
        )
        return msg, smp, t

    return Stream(name, emit, make)


def rtk_stream(
    receiver_id: int,
    epoch0_s: float,
    t_fix_s: FloatArray,
    baseline_ned_m: FloatArray,
    accuracy_m: FloatArray,
    nsats: list[int],
    fixed: list[bool],
    latency_s: float,
    clock_offset_s: FloatArray | None = None,
) -> Stream:
    """GPS_RTK / GPS2_RTK at the given fix times (only sent while in RTK); the week and
    time of week are the receiver's (late by ``-clock_offset_s`` under meaconing)."""
    emit = t_fix_s + latency_s + 0.003
    name = "GPS_RTK" if receiver_id == 0 else "GPS2_RTK"
    cls = mav.MAVLink_gps_rtk_message if receiver_id == 0 else mav.MAVLink_gps2_rtk_message

    def make(i: int, t_rx: float, last: float | None) -> tuple[Any, Sample | None, float | None]:
        ms = round(float(t_fix_s[i]) * units.MS_PER_S)
        gps_s = epoch0_s + float(t_fix_s[i]) - GPS_EPOCH_UNIX_S + GPS_LEAP_S
        if clock_offset_s is not None:
            gps_s += float(clock_offset_s[i])
        wn = int(gps_s // 604800)
        tow = round((gps_s - wn * 604800) * units.MS_PER_S)
        base = [_i(x * units.MM_PER_M, -(2**31), 2**31 - 1) for x in baseline_ned_m[i]]
        acc = _i(float(accuracy_m[i]) * units.MM_PER_M, 0, 2**32 - 1)
        iar = 1 if fixed[i] else 8
        msg = cls(ms, receiver_id, wn, tow, 1, 1, nsats[i], 1, *base, acc, iar)
        if last is None:
            return msg, None, None
        smp = RtkStatus(
            last, t_rx, receiver_id, 1, 1.0, nsats[i], np.array(base) / units.MM_PER_M, acc, iar
        )
        return msg, smp, None

    return Stream(name, emit, make)


_STATES = {
    0: InterferenceState.UNKNOWN,
    1: InterferenceState.CLEAN,
    2: InterferenceState.MITIGATED,
    3: InterferenceState.DETECTED,
}
"""GPS_JAMMING_STATE / GPS_SPOOFING_STATE -> InterferenceState."""


def gnss_integrity_stream(emit_s: FloatArray, jamming: list[int], spoofing: list[int]) -> Stream:
    """GNSS_INTEGRITY (id 441, MAVLink's development dialect) for receiver 0, as PX4's
    mavlink module sends it from its first GNSS receiver: the receiver's jamming and
    spoofing states, authentication and RAIM unknown (0; ``raim_hfom``/``raim_vfom``
    65535), the quality figures not available (255), no system error.

    PX4 fills ``id`` with the low byte of the receiver's device id; this stream sends the
    receiver's instance (0), as the message's definition asks.
    """
    from pymavlink.dialects.v20 import development as dev

    def make(i: int, t_rx: float, last: float | None) -> tuple[Any, Sample | None, float | None]:
        msg = dev.MAVLink_gnss_integrity_message(
            0, 0, 0, jamming[i], spoofing[i], 0, 65535, 65535, 255, 255, 255, 255
        )
        if last is None:
            return msg, None, None
        smp = GnssSignalReport(last, 0, "autopilot", _STATES[jamming[i]], _STATES[spoofing[i]])
        return msg, smp, None

    return Stream("GNSS_INTEGRITY", emit_s, make)


# --------------------------------------------------------------------------- housekeeping


def heartbeat_stream(
    emit_s: FloatArray, ardupilot: bool, fixed_wing: bool, armed: list[bool]
) -> Stream:
    """HEARTBEAT at 1 Hz (autopilot 3 ArduPilot / 12 PX4)."""
    ap = mav.MAV_AUTOPILOT_ARDUPILOTMEGA if ardupilot else mav.MAV_AUTOPILOT_PX4
    vtype = mav.MAV_TYPE_FIXED_WING if fixed_wing else mav.MAV_TYPE_QUADROTOR

    def make(i: int, t_rx: float, last: float | None) -> tuple[Any, Sample | None, float | None]:
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            mav.MAV_MODE_FLAG_SAFETY_ARMED if armed[i] else 0
        )
        status = mav.MAV_STATE_ACTIVE if armed[i] else mav.MAV_STATE_STANDBY
        msg = mav.MAVLink_heartbeat_message(vtype, ap, base, 0, status, 3)
        if last is None:
            return msg, None, None
        return msg, HeartbeatSample(last, t_rx, 1, ap, vtype, armed[i], status), None

    return Stream("HEARTBEAT", emit_s, make)


def system_time_stream(emit_s: FloatArray, epoch0_s: float) -> Stream:
    """SYSTEM_TIME at 1 Hz: the UNIX-epoch / boot-time pair (no typed sample)."""

    def make(i: int, t_rx: float, _last: float | None) -> tuple[Any, Sample | None, float | None]:
        ms = round(float(emit_s[i]) * units.MS_PER_S)
        unix_us = round(epoch0_s * units.US_PER_S) + ms * 1000
        return mav.MAVLink_system_time_message(unix_us, ms), None, None

    return Stream("SYSTEM_TIME", emit_s, make)


def vfr_hud_stream(
    emit_s: FloatArray,
    airspeed_mps: FloatArray,
    ground_speed_mps: FloatArray,
    yaw_rad: FloatArray,
    alt_msl_m: FloatArray,
    climb_mps: FloatArray,
    throttle: list[int],
) -> Stream:
    """VFR_HUD: speeds (float32), heading (integer degrees), MSL altitude, climb."""
    a32 = airspeed_mps.astype(np.float32).tolist()
    g32 = ground_speed_mps.astype(np.float32).tolist()
    alt32 = alt_msl_m.astype(np.float32).tolist()
    c32 = climb_mps.astype(np.float32).tolist()
    hdg = (np.rint(np.degrees(yaw_rad) % 360.0).astype(int) % 360).tolist()

    def make(i: int, t_rx: float, last: float | None) -> tuple[Any, Sample | None, float | None]:
        msg = mav.MAVLink_vfr_hud_message(a32[i], g32[i], hdg[i], throttle[i], alt32[i], c32[i])
        if last is None:
            return msg, None, None
        smp = VfrHudSample(last, t_rx, a32[i], g32[i], math.radians(hdg[i]), alt32[i], c32[i])
        return msg, smp, None

    return Stream("VFR_HUD", emit_s, make)


def ext_sys_state_stream(emit_s: FloatArray, landed: list[LandedState]) -> Stream:
    """EXTENDED_SYS_STATE: landed state from the flight phase."""

    def make(i: int, t_rx: float, last: float | None) -> tuple[Any, Sample | None, float | None]:
        msg = mav.MAVLink_extended_sys_state_message(0, int(landed[i]))
        if last is None:
            return msg, None, None
        return msg, LandedStateSample(last, t_rx, landed[i]), None

    return Stream("EXTENDED_SYS_STATE", emit_s, make)


def global_position_stream(
    t_s: FloatArray,
    lat_rad: FloatArray,
    lon_rad: FloatArray,
    alt_msl_m: FloatArray,
    alt0_m: float,
    vel_ned_mps: FloatArray,
    yaw_rad: FloatArray,
) -> Stream:
    """The autopilot's own GLOBAL_POSITION_INT (for comparison only)."""
    ms = np.rint(t_s * units.MS_PER_S).astype(np.int64).tolist()
    lat = np.rint(lat_rad * units.DEGE7_PER_RAD).astype(np.int64).tolist()
    lon = np.rint(lon_rad * units.DEGE7_PER_RAD).astype(np.int64).tolist()
    alt = np.rint(alt_msl_m * units.MM_PER_M).astype(np.int64).tolist()
    rel = np.rint((alt_msl_m - alt0_m) * units.MM_PER_M).astype(np.int64).tolist()
    vel = np.clip(np.rint(vel_ned_mps * units.CM_PER_M), -32768, 32767).astype(int).tolist()
    hdg = (np.rint((yaw_rad % (2 * np.pi)) * units.CDEG_PER_RAD).astype(int) % 36000).tolist()

    def make(i: int, t_rx: float, _last: float | None) -> tuple[Any, Sample | None, float | None]:
        msg = mav.MAVLink_global_position_int_message(
            ms[i], lat[i], lon[i], alt[i], rel[i], *vel[i], hdg[i]
        )
        t = ms[i] / units.MS_PER_S
        smp = AutopilotSolution(
            t,
            t_rx,
            lat[i] * _RAD_PER_DEGE7,
            lon[i] * _RAD_PER_DEGE7,
            alt[i] / units.MM_PER_M,
            np.array(vel[i], dtype=float) / units.CM_PER_M,
            yaw if (yaw := hdg[i] * _RAD_PER_CDEG) <= math.pi else yaw - 2.0 * math.pi,
        )
        return msg, smp, t

    return Stream("GLOBAL_POSITION_INT", t_s + 0.003, make)


def baro_stream(t_s: FloatArray, p_hpa: FloatArray, temp_c: FloatArray) -> Stream:
    """SCALED_PRESSURE (hPa float32, cdegC) and its :class:`BaroSample` as decoded."""
    ms = np.rint(t_s * units.MS_PER_S).astype(np.int64).tolist()
    p_l = p_hpa.astype(np.float32).tolist()
    c_l = np.rint(temp_c * 100.0).astype(int).tolist()

    def make(i: int, t_rx: float, _last: float | None) -> tuple[Any, Sample | None, float | None]:
        msg = mav.MAVLink_scaled_pressure_message(ms[i], p_l[i], 0.0, c_l[i], 0)
        t = ms[i] / units.MS_PER_S
        smp = BaroSample(t, t_rx, p_l[i] * 100.0, c_l[i] / 100.0, 0, "SCALED_PRESSURE")
        return msg, smp, t

    return Stream("SCALED_PRESSURE", t_s + 0.005, make)
