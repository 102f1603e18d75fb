"""Stream requests and the rate monitor."""

from __future__ import annotations

import pytest

from companion.mavlink.framing import FrameParser
from companion.mavlink.streams import RateMonitor, select_streams, stream_requests
from companion.types import AutopilotFlavour
from tests.mavlink._util import Packer

RATES = {"RAW_IMU": 50.0, "ATTITUDE": 25.0, "GPS_RAW_INT": 5.0, "SCALED_IMU2": 0.0}


def test_set_message_interval_for_each_message() -> None:
    msgs = stream_requests(1, 1, AutopilotFlavour.PX4, RATES)
    assert len(msgs) == 4  # no REQUEST_DATA_STREAM for PX4
    got = {(m.command, int(m.param1)): m.param2 for m in msgs}
    assert got == {(511, 27): 20_000.0, (511, 30): 40_000.0, (511, 24): 200_000.0, (511, 116): -1.0}
    assert all(m.target_system == 1 and m.target_component == 1 for m in msgs)
    # they pack and parse
    pk = Packer(1, 191)
    assert len(FrameParser().feed(b"".join(pk(m) for m in msgs))) == 4


def test_no_group_requests_for_ardupilot() -> None:
    """A group request raises every message of the group: ArduPilot gets per-message
    requests only."""
    msgs = stream_requests(1, 1, AutopilotFlavour.ARDUPILOT, RATES)
    assert [m.get_type() for m in msgs] == ["COMMAND_LONG"] * 4


def test_request_data_stream_fallback_for_an_unknown_autopilot() -> None:
    msgs = stream_requests(1, 1, AutopilotFlavour.UNKNOWN, RATES)
    rds = [m for m in msgs if m.get_type() == "REQUEST_DATA_STREAM"]
    by_id = {m.req_stream_id: (m.req_message_rate, m.start_stop) for m in rds}
    # RAW_SENSORS carries RAW_IMU (50) and SCALED_IMU2 (0): the group runs at 50 Hz
    assert by_id == {1: (50, 1), 2: (5, 1), 10: (25, 1)}


def test_one_imu_stream_selected_within_the_cap() -> None:
    rates = {"RAW_IMU": 50.0, "SCALED_IMU2": 50.0, "HIGHRES_IMU": 60.0, "ATTITUDE": 25.0}
    assert select_streams(AutopilotFlavour.ARDUPILOT, rates, 40.0) == {
        "RAW_IMU": 40.0,
        "ATTITUDE": 25.0,
    }
    assert select_streams(AutopilotFlavour.PX4, rates) == {"HIGHRES_IMU": 60.0, "ATTITUDE": 25.0}
    assert select_streams(AutopilotFlavour.UNKNOWN, rates) == rates


def test_bad_requests_raise() -> None:
    with pytest.raises(ValueError):
        stream_requests(1, 1, AutopilotFlavour.PX4, {"NOT_A_MESSAGE": 1.0})
    with pytest.raises(ValueError):
        stream_requests(1, 1, AutopilotFlavour.PX4, {"ATTITUDE": -1.0})


def test_rate_monitor_flags_1hz_when_10hz_requested() -> None:
    mon = RateMonitor({"RAW_IMU": 10.0, "ATTITUDE": 10.0}, window_s=5.0)
    t = 0.0
    for i in range(200):  # 20 s: ATTITUDE at 10 Hz, RAW_IMU at 1 Hz
        t = 0.1 * i
        mon.observe("ATTITUDE", t)
        if i % 10 == 0:
            mon.observe("RAW_IMU", t)
    short = mon.shortfalls(t)
    assert len(short) == 1 and short[0].startswith("RAW_IMU at 1.0 Hz")
    assert mon.measured_hz("ATTITUDE", t) == pytest.approx(10.0)


def test_rate_monitor_quiet_during_first_window_and_at_75_percent() -> None:
    mon = RateMonitor({"ATTITUDE": 10.0}, window_s=4.0)
    for i in range(300):
        if i % 4 != 0:  # 7.5 Hz, above 70 % of 10 Hz
            mon.observe("ATTITUDE", 0.1 * i)
        if 0.1 * i < 4.0:
            assert mon.shortfalls(0.1 * i) == []
    assert mon.shortfalls(29.9) == []
    assert mon.shortfalls(40.0) == ["ATTITUDE at 0.0 Hz, requested 10 Hz"]  # it stopped


def test_rate_monitor_accepts_pymavlink_class_names() -> None:
    mon = RateMonitor({"RAW_IMU": 10.0}, window_s=1.0)
    for i in range(30):
        mon.observe("MAVLink_raw_imu_message", i / 10)
    assert mon.measured_hz("RAW_IMU", 2.9) == pytest.approx(10.0)
    assert mon.shortfalls(2.9) == []
