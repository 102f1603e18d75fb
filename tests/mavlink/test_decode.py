"""Decoder: exact SI values from known MAVLink integers, time reconstruction, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink import units
from companion.mavlink.decode import Decoder, DecoderConfig
from companion.mavlink.ids import (
    MAV_CMD_USER_1,
    MAV_RESULT_DENIED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
)
from companion.nav.rotations import euler_to_quat
from companion.types import (
    AttitudeSample,
    AutopilotFlavour,
    AutopilotSolution,
    FixType,
    GnssFix,
    HeadingAction,
    HeadingCommand,
    HeartbeatSample,
    ImuSample,
    LandedState,
    LandedStateSample,
    RebootEvent,
    RtkStatus,
    VfrHudSample,
)
from tests.mavlink._util import Packer, attitude, gps_raw, heartbeat, raw_imu

G = units.STANDARD_GRAVITY_MPS2
DEG = math.pi / 180.0
AP = Packer()
GCS = Packer(255, 190)
OWN = Packer(1, 191)


def ready(flavour_autopilot: int = 3, t_ms: int = 10_000) -> Decoder:
    """A decoder locked on system 1 with a boot clock at t_ms."""
    d = Decoder()
    assert d.decode(AP.parsed(heartbeat(flavour_autopilot)), 0.0) == []  # no time yet
    assert len(d.decode(AP.parsed(attitude(t_ms)), 0.0)) == 1
    return d


def one(d: Decoder, msg: object, t_rx: float = 1.0) -> object:
    out = d.decode(AP.parsed(msg), t_rx)
    assert len(out) == 1, (out, d.rejections)
    return out[0]


# ------------------------------------------------------------------ round trips


def test_gps_raw_int_exact_values() -> None:
    d = ready()
    s = one(d, gps_raw(9_990_000))
    assert isinstance(s, GnssFix)
    assert s.t_s == 9.99 and s.t_rx_s == 1.0
    assert s.receiver_id == 0 and s.fix_type is FixType.FIX_3D
    assert s.lat_rad == pytest.approx(47.3977420 * DEG, abs=1e-15)
    assert s.lon_rad == pytest.approx(8.5455940 * DEG, abs=1e-15)
    assert s.alt_msl_m == 500.0 and s.alt_hae_m == 548.0
    assert s.hdop == 1.2 and s.vdop == 2.0 and s.satellites == 12
    assert s.ground_speed_mps == 15.0
    assert s.course_rad == pytest.approx(0.5 * math.pi, abs=1e-15)
    assert s.vel_ne_mps is not None
    np.testing.assert_allclose(s.vel_ne_mps, [0.0, 15.0], atol=1e-12)
    assert s.h_acc_m == 0.8 and s.v_acc_m == 1.2 and s.vel_acc_mps == 0.15
    assert s.dgps_age_s is None


def test_gps_sentinels_give_none_and_no_fix_still_decodes() -> None:
    d = ready()
    msg = gps_raw(
        9_990_000,
        fix=1,
        lat=0,
        lon=0,
        alt=0,
        eph=65535,
        epv=65535,
        vel=65535,
        cog=65535,
        sats=255,
        alt_ell=0,
        h_acc=0,
        v_acc=0,
        vel_acc=0,
    )
    s = one(d, msg)
    assert isinstance(s, GnssFix)
    assert s.fix_type is FixType.NO_FIX
    assert s.hdop is None and s.vdop is None and s.satellites is None and s.alt_hae_m is None
    assert s.vel_ne_mps is None and s.course_rad is None and s.ground_speed_mps == 0.0
    assert s.h_acc_m is None and s.v_acc_m is None and s.vel_acc_mps is None
    s2 = one(d, gps_raw(9_995_000, cog=65535))
    assert isinstance(s2, GnssFix)
    assert s2.ground_speed_mps == 15.0 and s2.course_rad is None and s2.vel_ne_mps is None


def test_gps2_raw() -> None:
    d = ready()
    m = apm.MAVLink_gps2_raw_message(
        9_000_000,
        6,
        -337000000,
        1512000000,
        -20_000,
        80,
        90,
        250,
        18000,
        20,
        10,
        1500,
        0,
        0,
        14,
        25,
        30,
        0,
    )
    s = one(d, m)
    assert isinstance(s, GnssFix)
    assert s.receiver_id == 1 and s.fix_type is FixType.RTK_FIXED and s.dgps_age_s == 1.5
    assert s.lat_rad == pytest.approx(-33.7 * DEG, abs=1e-15)
    assert s.lon_rad == pytest.approx(151.2 * DEG, abs=1e-15)
    assert s.alt_msl_m == -20.0 and s.alt_hae_m is None
    assert s.h_acc_m == 0.014 and s.v_acc_m == 0.025 and s.vel_acc_mps == 0.03
    assert s.vel_ne_mps is not None
    np.testing.assert_allclose(s.vel_ne_mps, [-2.5, 0.0], atol=1e-12)


@pytest.mark.parametrize(
    "cls,rid", [(apm.MAVLink_gps_rtk_message, 0), (apm.MAVLink_gps2_rtk_message, 1)]
)
def test_gps_rtk(cls: type, rid: int) -> None:
    d = ready()
    s = one(d, cls(123, 0, 2200, 3000, 1, 5, 14, 1, 1500, -2500, 300, 42, 3))
    assert isinstance(s, RtkStatus)
    assert s.t_s == 10.0  # the latest boot clock, not time_last_baseline_ms
    assert s.receiver_id == rid and s.health == 1 and s.rate_hz == 5.0 and s.satellites == 14
    np.testing.assert_array_equal(s.baseline_m, [1.5, -2.5, 0.3])
    assert s.accuracy == 42 and s.iar_num_hypotheses == 3


def test_raw_and_scaled_imu_mg_mrad() -> None:
    d = ready()
    s = one(d, raw_imu(10_020_000, zacc=-1000, imu_id=2))
    assert isinstance(s, ImuSample)
    assert s.t_s == 10.02 and s.imu_id == 2 and s.source == "RAW_IMU"
    np.testing.assert_allclose(s.acc_b_mps2, [0.01 * G, -0.02 * G, -G], rtol=1e-15)
    np.testing.assert_allclose(s.gyro_b_radps, [0.001, -0.002, 0.003], rtol=1e-15)
    for cls, name, iid in (
        (apm.MAVLink_scaled_imu_message, "SCALED_IMU", 0),
        (apm.MAVLink_scaled_imu2_message, "SCALED_IMU2", 1),
        (apm.MAVLink_scaled_imu3_message, "SCALED_IMU3", 2),
    ):
        d = ready()  # one IMU stream per decoder: the others are not used
        s = one(d, cls(10_040, 500, 0, -980, -100, 200, 0, 0, 0, 0, 0))
        assert isinstance(s, ImuSample)
        assert s.t_s == 10.04 and s.imu_id == iid and s.source == name
        np.testing.assert_allclose(s.acc_b_mps2, [0.5 * G, 0.0, -0.98 * G], rtol=1e-15)
        np.testing.assert_allclose(s.gyro_b_radps, [-0.1, 0.2, 0.0], rtol=1e-15)


def test_one_imu_stream_used() -> None:
    """ArduPilot sends RAW_IMU (IMU 0) and SCALED_IMU2 (IMU 1): one is used, the other
    counted as unused; when the chosen one stops, the other takes over."""
    d = ready()
    used: list[str] = []
    for k in range(20):  # both at 50 Hz, interleaved
        t_ms = 10_000 + 20 * k
        for msg in (
            raw_imu(t_ms * 1000, zacc=-1000),
            apm.MAVLink_scaled_imu2_message(t_ms, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0),
        ):
            used += [s.source for s in d.decode(AP.parsed(msg), 1.0) if isinstance(s, ImuSample)]
    assert used == ["RAW_IMU"] * 20
    assert d.rejections["unused_imu_stream"] == 20
    for k in range(20, 60):  # RAW_IMU stops: SCALED_IMU2 takes over after 0.5 s
        t_ms = 10_000 + 20 * k
        msg = apm.MAVLink_scaled_imu2_message(t_ms, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0)
        used += [s.source for s in d.decode(AP.parsed(msg), 1.0) if isinstance(s, ImuSample)]
    assert 10 <= used.count("SCALED_IMU2") <= 40


def test_repeated_fix_is_no_new_fix() -> None:
    """ArduPlane's 10 Hz GPS_RAW_INT repeats each 5 Hz fix: the repeat is no new fix."""
    d = ready()
    fixes = 0
    for k in range(10):
        t_us = 10_000_000 + 200_000 * (k // 2)  # each fix sent twice
        msg = apm.MAVLink_gps_raw_int_message(
            t_us, 3, 520_000_000 + k // 2, 209_000_000, 110_000, 100, 100, 2300, 0, 12
        )
        fixes += sum(isinstance(s, GnssFix) for s in d.decode(AP.parsed(msg), 1.0))
    assert fixes == 5
    assert d.rejections["repeated_fix"] == 5


def test_highres_imu_si() -> None:
    d = ready(12)
    m = apm.MAVLink_highres_imu_message(
        10_010_000, 0.5, -0.25, -9.75, 0.125, -0.0625, 1.5, 0, 0, 0, 1013, 0, 100, 20, 0x3F, 1
    )
    s = one(d, m)
    assert isinstance(s, ImuSample)
    assert s.t_s == 10.01 and s.imu_id == 1 and s.source == "HIGHRES_IMU"
    np.testing.assert_array_equal(s.acc_b_mps2, [0.5, -0.25, -9.75])
    np.testing.assert_array_equal(s.gyro_b_radps, [0.125, -0.0625, 1.5])
    assert d.flavour is AutopilotFlavour.PX4


def test_attitude_and_quaternion() -> None:
    d = ready()
    s = one(d, apm.MAVLink_attitude_message(10_020, 0.5, -0.25, 3.0, 0.125, 0.25, -0.5))
    assert isinstance(s, AttitudeSample)
    assert (s.roll_rad, s.pitch_rad, s.yaw_rad) == (0.5, -0.25, 3.0)
    np.testing.assert_array_equal(s.rate_b_radps, [0.125, 0.25, -0.5])
    q = euler_to_quat(0.3, -0.2, -2.5)
    s = one(d, apm.MAVLink_attitude_quaternion_message(10_030, *q, 0.1, 0.2, 0.3, [0, 0, 0, 0]))
    assert isinstance(s, AttitudeSample)
    assert s.t_s == 10.03
    # float32 quaternion components: ~1e-7 rad
    assert s.roll_rad == pytest.approx(0.3, abs=1e-6)
    assert s.pitch_rad == pytest.approx(-0.2, abs=1e-6)
    assert s.yaw_rad == pytest.approx(-2.5, abs=1e-6)


def test_heartbeat_flavour_extended_state_vfr_hud() -> None:
    d = ready(3)
    assert d.flavour is AutopilotFlavour.ARDUPILOT and d.system_id == 1
    s = one(d, heartbeat(3, base_mode=128 | 1, status=4))
    assert isinstance(s, HeartbeatSample)
    assert s.armed and s.system_status == 4 and s.system_id == 1 and s.t_s == 10.0
    s = one(d, apm.MAVLink_extended_sys_state_message(0, 2))
    assert isinstance(s, LandedStateSample) and s.landed_state is LandedState.IN_AIR
    s = one(d, apm.MAVLink_vfr_hud_message(25.5, 24.0, 270, 50, 312.5, -1.5))
    assert isinstance(s, VfrHudSample)
    assert (s.airspeed_mps, s.ground_speed_mps, s.alt_msl_m, s.climb_mps) == (25.5, 24, 312.5, -1.5)
    assert s.heading_rad == pytest.approx(1.5 * math.pi, abs=1e-15)
    assert s.t_s == 10.0


def test_global_position_int_from_autopilot() -> None:
    d = ready()
    m = apm.MAVLink_global_position_int_message(
        10_050, 473977420, 85455940, 500_000, 12_000, 150, -250, 75, 27000
    )
    s = one(d, m)
    assert isinstance(s, AutopilotSolution)
    assert s.t_s == 10.05 and s.alt_msl_m == 500.0
    np.testing.assert_allclose(s.vel_ned_mps, [1.5, -2.5, 0.75], rtol=1e-15)
    assert s.yaw_rad == pytest.approx(-0.5 * math.pi, abs=1e-12)
    m2 = apm.MAVLink_global_position_int_message(10_060, 0, 0, 0, 0, 0, 0, 0, 65535)
    s2 = one(d, m2)
    assert isinstance(s2, AutopilotSolution) and s2.yaw_rad is None
    # the same message from another component of the autopilot's system is not the autopilot's
    other = Packer(1, 154)
    assert d.decode(other.parsed(m), 0.0) == []
    assert d.rejections["not_autopilot_component"] == 1


def test_heading_confirmation_command() -> None:
    d = ready()
    actions = ((1.0, HeadingAction.CONFIRM), (0.0, HeadingAction.REFUSE), (2.0, HeadingAction.UNDO))
    for p1, action in actions:
        m = apm.MAVLink_command_long_message(1, 191, MAV_CMD_USER_1, 0, p1, 0, 0, 0, 0, 0, 0)
        out = d.decode(GCS.parsed(m), 2.0)
        assert out == [HeadingCommand(t_s=10.0, t_rx_s=2.0, action=action)]
        taken = d.take_command()
        assert taken is not None and taken.result is None and taken.request.source_system == 255
        assert d.take_command() is None  # once
    # COMMAND_INT carries it too (x, y are integers there)
    mi = apm.MAVLink_command_int_message(0, 191, 0, MAV_CMD_USER_1, 0, 0, 1.0, 0, 0, 0, 0, 0, 0)
    assert d.decode(GCS.parsed(mi), 2.0) == [
        HeadingCommand(t_s=10.0, t_rx_s=2.0, action=HeadingAction.CONFIRM)
    ]
    taken = d.take_command()
    assert taken is not None and taken.request.message == "COMMAND_INT"
    for p1 in (0.5, 3.0, -1.0, float("nan")):
        bad = apm.MAVLink_command_long_message(1, 191, MAV_CMD_USER_1, 0, p1, 0, 0, 0, 0, 0, 0)
        assert d.decode(GCS.parsed(bad), 2.0) == []
        taken = d.take_command()
        assert taken is not None and taken.result == MAV_RESULT_DENIED and "param1" in taken.reason
    other = apm.MAVLink_command_long_message(1, 1, MAV_CMD_USER_1, 0, 1.0, 0, 0, 0, 0, 0, 0)
    assert d.decode(GCS.parsed(other), 2.0) == [] and d.take_command() is None
    assert d.rejections["bad_command_param"] == 4 and d.rejections["not_for_us"] == 1
    assert d.accepted["COMMAND_LONG"] == 3 and d.accepted["COMMAND_INT"] == 1


def test_other_commands_addressed_to_us_are_unsupported_broadcasts_are_not_ours() -> None:
    d = ready()
    for kind in ("long", "int"):
        for target, answered in ((191, True), (0, False), (1, False)):
            if kind == "long":
                m = apm.MAVLink_command_long_message(1, target, 512, 0, 33, 0, 0, 0, 0, 0, 0)
            else:
                m = apm.MAVLink_command_int_message(1, target, 0, 512, 0, 0, 33, 0, 0, 0, 0, 0, 0)
            assert d.decode(GCS.parsed(m), 2.0) == []
            taken = d.take_command()
            if answered:
                assert taken is not None and taken.result == MAV_RESULT_UNSUPPORTED
                assert taken.request.command == 512
            else:
                assert taken is None
    assert d.rejections["unsupported_command"] == 2 and d.rejections["unhandled_type"] == 4


def test_heading_command_before_the_clock_is_temporarily_rejected() -> None:
    d = Decoder()
    m = apm.MAVLink_command_long_message(0, 191, MAV_CMD_USER_1, 0, 1.0, 0, 0, 0, 0, 0, 0)
    assert d.decode(GCS.parsed(m), 2.0) == []
    taken = d.take_command()
    assert taken is not None and taken.result == MAV_RESULT_TEMPORARILY_REJECTED
    assert d.rejections["no_time_yet"] == 1


# ------------------------------------------------------------------ identity filters


def test_sysid_lock_and_filters() -> None:
    d = Decoder()
    assert d.decode(AP.parsed(attitude(1000)), 0.0) == []
    assert d.rejections["no_system_yet"] == 1
    # a GCS heartbeat does not lock
    assert d.decode(GCS.parsed(heartbeat(8)), 0.0) == []
    assert d.system_id is None and d.rejections["not_autopilot"] == 1
    d.decode(AP.parsed(heartbeat(3)), 0.0)
    assert d.system_id == 1
    other = Packer(2, 1)
    assert d.decode(other.parsed(attitude(1000)), 0.0) == []
    assert d.rejections["wrong_sysid"] == 1
    assert d.decode(OWN.parsed(heartbeat(3)), 0.0) == []
    assert d.decode(OWN.parsed(attitude(1000)), 0.0) == []
    assert d.rejections["own_message"] == 2
    assert d.decode(AP.parsed(apm.MAVLink_sys_status_message(*([0] * 13))), 0.0) == []
    assert d.rejections["unhandled_type"] == 1
    d2 = Decoder(DecoderConfig(system_id=2))
    assert len(d2.decode(other.parsed(attitude(1000)), 0.0)) == 1


# ------------------------------------------------------------------ time


def test_epoch_gps_time_is_mapped_onto_boot_clock() -> None:
    """Boot clock at 100 Hz; GPS epoch-stamped with true offset E and 120 ms latency;
    no SYSTEM_TIME (and no wait for it): the running-maximum estimate."""
    d = Decoder(DecoderConfig(system_time_wait_s=0.0))
    d.decode(AP.parsed(heartbeat()), 0.0)
    epoch0 = 1_700_000_000.0
    # no boot time yet -> rejected
    assert d.decode(AP.parsed(gps_raw(int(epoch0 * 1e6))), 0.0) == []
    assert d.rejections["no_time_yet"] == 2  # heartbeat + gps
    fixes = []
    for i in range(1000):  # 10 s of 100 Hz attitude
        t_ms = 5000 + 10 * i
        d.decode(AP.parsed(attitude(t_ms)), 0.0)
        if i % 20 == 12:  # 5 Hz GPS, valid 120 ms before it is sent
            t_fix = t_ms / 1000 - 0.12
            out = d.decode(AP.parsed(gps_raw(int(round((epoch0 + t_fix) * 1e6)))), 0.0)
            fixes.append((t_fix, out[0].t_s))
    errs = np.array([t_s - t_fix for t_fix, t_s in fixes])
    # mapped time is late by the smallest latency behind the boot clock (120 ms here)
    np.testing.assert_allclose(errs, 0.12, atol=2e-6)
    assert d.epoch_offset_s == pytest.approx(epoch0 - 0.12, abs=2e-6)


def test_zero_gps_time_takes_latest_clock() -> None:
    d = ready()
    s = one(d, gps_raw(0, fix=0))
    assert isinstance(s, GnssFix) and s.t_s == 10.0


def test_small_backwards_step_is_rejected_per_stream() -> None:
    d = ready(t_ms=10_000)
    assert len(d.decode(AP.parsed(attitude(10_020)), 0.0)) == 1
    assert d.decode(AP.parsed(attitude(10_010)), 0.0) == []
    assert d.rejections["time_backwards"] == 1
    # another stream slightly behind the attitude one is fine
    assert len(d.decode(AP.parsed(raw_imu(10_015_000)), 0.0)) == 1
    assert d.reboots == 0


def test_reboot_detected_and_clock_reset() -> None:
    d = ready(t_ms=600_000)
    d.decode(AP.parsed(raw_imu(600_010_000)), 0.0)
    out = d.decode(AP.parsed(attitude(1500)), 3.0)
    assert len(out) == 2
    assert out[0] == RebootEvent(t_s=1.5, t_rx_s=3.0, previous_t_s=600.01)
    assert isinstance(out[1], AttitudeSample) and out[1].t_s == 1.5
    assert d.reboots == 1 and d.last_t_s == 1.5
    # streams restart from the new clock without time_backwards
    assert one(d, raw_imu(1_510_000)).t_s == 1.51  # type: ignore[attr-defined]
    assert d.rejections["time_backwards"] == 0


def test_time_boot_ms_wrap() -> None:
    d = Decoder()
    d.decode(AP.parsed(heartbeat()), 0.0)
    wrap = 2**32
    out = []
    for t_ms in (wrap - 40, wrap - 20, 0, 20):
        out += d.decode(AP.parsed(attitude(t_ms)), 0.0)
    assert [s.t_s for s in out] == [
        (wrap - 40) / 1e3,
        (wrap - 20) / 1e3,
        wrap / 1e3,
        (wrap + 20) / 1e3,
    ]
    # a straggler from before the wrap on another stream
    s = d.decode(
        AP.parsed(apm.MAVLink_scaled_imu2_message(wrap - 10, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0)), 0.0
    )
    assert s[0].t_s == (wrap - 10) / 1e3
    assert d.reboots == 0


# ------------------------------------------------------------------ validation


NAN = float("nan")
INF = float("inf")


@pytest.mark.parametrize(
    "msg,reason",
    [
        (apm.MAVLink_attitude_message(10_020, NAN, 0, 0, 0, 0, 0), "nan_field"),
        (apm.MAVLink_attitude_message(10_020, 0, 0, 0, INF, 0, 0), "nan_field"),
        (apm.MAVLink_attitude_message(10_020, 4.0, 0, 0, 0, 0, 0), "attitude_out_of_range"),
        (apm.MAVLink_attitude_message(10_020, 0, 0, 0, 0, 60.0, 0), "attitude_out_of_range"),
        (
            apm.MAVLink_attitude_quaternion_message(10_020, 0.5, 0, 0, 0, 0, 0, 0, [0] * 4),
            "bad_quaternion",
        ),
        (
            apm.MAVLink_highres_imu_message(
                10_010_000, NAN, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
            ),
            "nan_field",
        ),
        (
            apm.MAVLink_highres_imu_message(
                10_010_000, 600.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
            ),
            "imu_out_of_range",
        ),
        (
            apm.MAVLink_highres_imu_message(
                10_010_000, 0, 0, 0, 0, 0, 70.0, 0, 0, 0, 0, 0, 0, 0, 0, 0
            ),
            "imu_out_of_range",
        ),
        (gps_raw(10_000_000, lat=910_000_000), "lat_out_of_range"),
        (gps_raw(10_000_000, lon=-1_800_000_001), "lon_out_of_range"),
        (gps_raw(10_000_000, alt=60_000_000), "alt_out_of_range"),
        (gps_raw(10_000_000, alt=-2_000_000), "alt_out_of_range"),
        (gps_raw(10_000_000, h_acc=200_000_000), "impossible_accuracy"),
        (gps_raw(10_000_000, vel=65000), "speed_out_of_range"),
        (gps_raw(10_000_000, fix=9), "bad_enum"),
        (apm.MAVLink_vfr_hud_message(NAN, 0, 0, 0, 0, 0), "nan_field"),
        (apm.MAVLink_vfr_hud_message(0, 0, 0, 0, 1e6, 0), "alt_out_of_range"),
        (apm.MAVLink_extended_sys_state_message(0, 9), "bad_enum"),
        (
            apm.MAVLink_global_position_int_message(10_050, 950_000_000, 0, 0, 0, 0, 0, 0, 0),
            "lat_out_of_range",
        ),
    ],
)
def test_rejections_by_reason(msg: object, reason: str) -> None:
    d = ready()
    assert d.decode(AP.parsed(msg), 0.0) == []
    assert d.rejections[reason] == 1
    assert sum(d.rejections.values()) == 2  # + the heartbeat before the clock


def test_bad_frame_counting_and_garbage_objects() -> None:
    d = ready()
    d.bad_frame(3)
    assert d.decode(object(), 0.0) == []
    assert d.rejections["corrupt_frame"] == 4


def test_good_messages_around_bad_ones_all_decoded() -> None:
    rng = np.random.default_rng(21)
    d = ready()
    rej0 = sum(d.rejections.values())
    n_good = 0
    good_iters = bad_iters = 0
    for i in range(400):
        t_ms = 10_020 + 10 * i
        if rng.random() < 0.3:
            bad = [
                apm.MAVLink_attitude_message(t_ms, NAN, 0, 0, 0, 0, 0),
                gps_raw(t_ms * 1000, lat=-950_000_000),
                apm.MAVLink_highres_imu_message(
                    t_ms * 1000, INF, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
                ),
            ][i % 3]
            assert d.decode(AP.parsed(bad), 0.0) == []
            bad_iters += 1
        else:
            n_good += len(d.decode(AP.parsed(attitude(t_ms)), 0.0))
            n_good += len(d.decode(AP.parsed(raw_imu(t_ms * 1000)), 0.0))
            good_iters += 1
    assert bad_iters > 80
    assert n_good == 2 * good_iters
    assert sum(d.rejections.values()) - rej0 == bad_iters
    assert d.rejections["nan_field"] + d.rejections["lat_out_of_range"] == bad_iters


_f32 = st.floats(allow_nan=True, allow_infinity=True, width=32)
_i32 = st.integers(-(2**31), 2**31 - 1)
_u16 = st.integers(0, 65535)
_u32 = st.integers(0, 2**32 - 1)
_u64 = st.integers(0, 2**64 - 1)
_u8 = st.integers(0, 255)
_i16 = st.integers(-32768, 32767)

_MESSAGES = st.one_of(
    st.builds(apm.MAVLink_attitude_message, _u32, _f32, _f32, _f32, _f32, _f32, _f32),
    st.builds(
        apm.MAVLink_attitude_quaternion_message,
        _u32,
        _f32,
        _f32,
        _f32,
        _f32,
        _f32,
        _f32,
        _f32,
        st.just([0.0] * 4),
    ),
    st.builds(
        apm.MAVLink_gps_raw_int_message,
        _u64,
        _u8,
        _i32,
        _i32,
        _i32,
        _u16,
        _u16,
        _u16,
        _u16,
        _u8,
        _i32,
        _u32,
        _u32,
        _u32,
        _u32,
        _u16,
    ),
    st.builds(
        apm.MAVLink_gps2_raw_message,
        _u64,
        _u8,
        _i32,
        _i32,
        _i32,
        _u16,
        _u16,
        _u16,
        _u16,
        _u8,
        _u8,
        _u32,
        _u16,
        _i32,
        _u32,
        _u32,
        _u32,
        _u32,
    ),
    st.builds(apm.MAVLink_raw_imu_message, _u64, *([_i16] * 9), _u8, _i16),
    st.builds(apm.MAVLink_scaled_imu2_message, _u32, *([_i16] * 10)),
    st.builds(apm.MAVLink_highres_imu_message, _u64, *([_f32] * 12), _u16, _u8),
    st.builds(apm.MAVLink_vfr_hud_message, _f32, _f32, _i16, _u16, _f32, _f32),
    st.builds(
        apm.MAVLink_global_position_int_message,
        _u32,
        _i32,
        _i32,
        _i32,
        _i32,
        _i16,
        _i16,
        _i16,
        _u16,
    ),
    st.builds(apm.MAVLink_extended_sys_state_message, _u8, _u8),
    st.builds(apm.MAVLink_heartbeat_message, _u8, _u8, _u8, _u32, _u8, st.just(3)),
    st.builds(
        apm.MAVLink_gps_rtk_message,
        _u32,
        _u8,
        _u16,
        _u32,
        _u8,
        _u8,
        _u8,
        _u8,
        _i32,
        _i32,
        _i32,
        _u32,
        _i32,
    ),
    st.builds(
        apm.MAVLink_command_long_message,
        _u8,
        _u8,
        st.sampled_from([MAV_CMD_USER_1, 400]),
        _u8,
        *([_f32] * 7),
    ),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(_MESSAGES, min_size=1, max_size=30))
def test_fuzzed_fields_never_crash_and_are_all_accounted(msgs: list) -> None:
    d = ready()
    base_acc, base_rej = sum(d.accepted.values()), sum(d.rejections.values())
    n_samples = 0
    for m in msgs:
        out = d.decode(AP.parsed(m), 0.0)
        for s in out:
            n_samples += 1
            for name in s.__slots__:
                v = getattr(s, name)
                if isinstance(v, float):
                    assert math.isfinite(v), (m, s)
                elif isinstance(v, np.ndarray):
                    assert np.all(np.isfinite(v)), (m, s)
    # every message is either accepted or rejected with a reason, exactly once
    assert sum(d.accepted.values()) - base_acc + sum(d.rejections.values()) - base_rej == len(msgs)
    assert n_samples >= sum(d.accepted.values()) - base_acc


def test_stale_gnss_time_during_outage_is_not_a_reboot() -> None:
    """A boot-stamped GPS_RAW_INT repeats its last-fix time through a 10 s outage."""
    d = ready(t_ms=10_000)
    stale_us = 9_800_000
    for i in range(1, 500):  # 10 s of 50 Hz attitude with 5 Hz GPS
        t_ms = 10_000 + 20 * i
        assert len(d.decode(AP.parsed(attitude(t_ms)), 0.0)) == 1
        if i % 10 == 0:
            out = d.decode(AP.parsed(gps_raw(stale_us, fix=1)), 0.0)
            assert len(out) == 1 and isinstance(out[0], GnssFix) and out[0].t_s == 9.8
    assert d.reboots == 0
    assert d.rejections["time_backwards"] == 0
    assert d.last_t_s == pytest.approx(19.98)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"system_id": 0}, r"system_id must be in \[1, 255\], got 0"),
        ({"max_speed_mps": -1.0}, r"max_speed_mps must be > 0, got -1.0"),
        ({"gnss_delay_s": 2.0}, r"gnss_delay_s must be in \[0, 1\], got 2.0"),
        ({"system_time_wait_s": 61.0}, r"system_time_wait_s must be in \[0, 60\], got 61.0"),
        ({"reboot_backjump_s": 0.0}, r"reboot_backjump_s must be > 0, got 0.0"),
        ({"alt_min_m": 10.0, "alt_max_m": 0.0}, r"alt_min_m must be < alt_max_m"),
    ],
)
def test_config_rejections_name_the_field(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        DecoderConfig(**kwargs)
    assert DecoderConfig(system_id=None).system_id is None
