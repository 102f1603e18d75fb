"""What the service takes from ArduPilot's own parameters (read over the parameter
protocol): the GPS instance fed by GPS_INPUT (its id, and its GPS2_RAW echo never taken
as a receiver), the receivers' lags, and stream requests it can honour."""

from __future__ import annotations

import logging
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.config import Config, StreamsConfig
from companion.mavlink.ids import MAV_CMD_SET_MESSAGE_INTERVAL
from companion.pipeline import Pipeline
from tests.mavlink._util import Packer, attitude, gps_raw, heartbeat

AP = Packer()
RX = apm.MAVLink(None)


def _msgs(frames: list[bytes]) -> list[Any]:
    return [RX.decode(bytearray(f)) for f in frames]


def _param(name: str, value: float) -> Any:
    return AP.parsed(apm.MAVLink_param_value_message(name.encode(), value, 9, 100, 0))


def _started(config: Config | None = None) -> tuple[Pipeline, list[Any]]:
    p = Pipeline(config)
    out = []
    for t_ms in (9_980, 10_000):  # the first HEARTBEAT comes before any time is known
        out += _msgs(p.on_message(AP.parsed(heartbeat(3)), 0.0))
        out += _msgs(p.on_message(AP.parsed(attitude(t_ms)), 0.0))
    return p, out


def _gps2_raw(t_us: int) -> Any:
    return apm.MAVLink_gps2_raw_message(
        t_us, 3, 473977420, 85455940, 500_000, 120, 200, 1500, 9000, 12, 0, 0, 0
    )


def test_params_read_and_streams_requested_per_message() -> None:
    p, out = _started()
    names = {m.param_id for m in out if m.get_type() == "PARAM_REQUEST_READ"}
    assert {"GPS1_TYPE", "GPS2_TYPE", "GPS1_DELAY_MS", "SCHED_LOOP_RATE"} <= names
    assert not [m for m in out if m.get_type() == "REQUEST_DATA_STREAM"]  # no group raised
    intervals = {
        int(m.param1): m.param2
        for m in out
        if m.get_type() == "COMMAND_LONG" and m.command == MAV_CMD_SET_MESSAGE_INTERVAL
    }
    imu_ids = {
        apm.MAVLINK_MSG_ID_RAW_IMU,
        apm.MAVLINK_MSG_ID_SCALED_IMU2,
        apm.MAVLINK_MSG_ID_SCALED_IMU3,
        apm.MAVLINK_MSG_ID_HIGHRES_IMU,
    }
    assert set(intervals) & imu_ids == {apm.MAVLINK_MSG_ID_RAW_IMU}  # one IMU stream


def test_rates_capped_at_the_loop_rate() -> None:
    """ArduPilot denies an interval (ms) times 800 below its loop period (us): 40 Hz at
    most on Plane's 50 Hz loop, asked before its loop rate is known; more once it is."""

    def raw_imu_interval_us(out: list[Any]) -> float:
        (interval,) = [
            m.param2
            for m in out
            if m.get_type() == "COMMAND_LONG"
            and m.command == MAV_CMD_SET_MESSAGE_INTERVAL
            and int(m.param1) == apm.MAVLINK_MSG_ID_RAW_IMU
        ]
        return float(interval)

    config = Config(streams=StreamsConfig(raw_imu_hz=100.0))
    p, out = _started(config)
    assert raw_imu_interval_us(out) == 25_000.0  # 40 Hz, not 100
    assert _msgs(p.on_message(_param("SCHED_LOOP_RATE", 50.0), 0.1)) == []  # no change
    out = _msgs(p.on_message(_param("SCHED_LOOP_RATE", 400.0), 0.1))
    assert raw_imu_interval_us(out) == 10_000.0  # 100 Hz: within 0.8 of 400 Hz


def test_gps_id_from_gps2_type_and_own_echo_ignored() -> None:
    p, _ = _started()
    assert p.encoder.gps_id == 0
    p.on_message(_param("GPS1_TYPE", 1.0), 0.1)
    assert not p.engine.autopilot_fuses_output
    p.on_message(_param("GPS2_TYPE", 14.0), 0.1)
    assert p.encoder.gps_id == 1
    assert p.engine.autopilot_fuses_output  # its attitude through a gap is built on ours
    p.on_message(AP.parsed(_gps2_raw(10_100_000)), 0.2)
    assert p.decoder.rejections["own_injection"] == 1
    p.on_message(AP.parsed(gps_raw(10_100_000)), 0.2)  # GPS 1 is still a receiver
    assert p.decoder.accepted["GPS_RAW_INT"] == 1


def test_configured_gps_id_kept_when_not_from_autopilot() -> None:
    from companion.mavlink.encode import EncoderConfig

    config = Config(encoder=EncoderConfig(gps_id=3, gps_id_from_autopilot=False))
    p, _ = _started(config)
    p.on_message(_param("GPS2_TYPE", 14.0), 0.1)
    assert p.encoder.gps_id == 3
    p.on_message(AP.parsed(_gps2_raw(10_100_000)), 0.2)  # not ours: a receiver
    assert p.decoder.rejections["own_injection"] == 0


def test_gps_lag_from_the_autopilot() -> None:
    p, _ = _started()
    p.on_message(_param("GPS1_DELAY_MS", 120.0), 0.1)
    fixes = p.decoder.decode(AP.parsed(gps_raw(10_100_000)), 0.2)
    assert [round(f.t_s, 6) for f in fixes] == [9.98]


def test_measured_gps_lag_taken_where_the_autopilot_gives_none() -> None:
    """GPS1_DELAY_MS 0 (the driver's default, unknown here): the lag measured in flight
    places the fixes, and stays through a new reading of the parameters."""
    from companion.engine.gnss_lag import MeasuredLag

    p, _ = _started()
    p.on_message(_param("GPS1_DELAY_MS", 0.0), 0.1)
    assert p._on_measured_lag(MeasuredLag(0.22, 0.015, 3), 10.0) == []  # noqa: SLF001
    assert p.decoder.gnss.delay_s[0] == pytest.approx(0.22)
    p.on_message(_param("GPS1_DELAY_MS", 0.0), 0.3)
    fixes = p.decoder.decode(AP.parsed(gps_raw(10_100_000)), 0.4)
    assert [round(f.t_s, 6) for f in fixes] == [9.88]


def test_measured_gps_lag_against_the_autopilot_parameter_used_and_announced() -> None:
    """GPS1_DELAY_MS is what the autopilot's filter assumes, not a measurement of the
    stamps it sends (ArduPilot SITL's 100 ms against 83 ms measured): a sure
    measurement places the fixes, says so, and stays through a new reading of the
    parameters."""
    from companion.engine.gnss_lag import MeasuredLag

    p, _ = _started()
    p.on_message(_param("GPS1_DELAY_MS", 100.0), 0.1)
    out = _msgs(p._on_measured_lag(MeasuredLag(0.083, 0.006, 4), 10.0))  # noqa: SLF001
    texts = [m.text for m in out if m.get_type() == "STATUSTEXT"]
    assert texts == ["CMP AP_CONFIG GPS1_DELAY_MS 100, lag 83+/-6 ms"]
    assert p.decoder.gnss.delay_s[0] == pytest.approx(0.083)
    p.on_message(_param("GPS1_DELAY_MS", 100.0), 0.3)
    fixes = p.decoder.decode(AP.parsed(gps_raw(10_100_000)), 0.4)
    assert [round(f.t_s, 6) for f in fixes] == [10.017]


def test_configured_gps_lag_kept_over_the_measured_one() -> None:
    from companion.engine.gnss_lag import MeasuredLag
    from companion.mavlink.decode.config import DecoderConfig

    p, _ = _started(Config(decoder=DecoderConfig(gnss_delay_s=0.2)))
    p.on_message(_param("GPS1_DELAY_MS", 100.0), 0.1)
    assert p._on_measured_lag(MeasuredLag(0.083, 0.006, 4), 10.0) == []  # noqa: SLF001
    assert p.decoder.gnss.delay_s[0] == pytest.approx(0.1)


def test_gps_id_from_autopilot_turned_off_live() -> None:
    import dataclasses

    p, _ = _started()
    p.on_message(_param("GPS2_TYPE", 14.0), 0.1)
    assert p.encoder.gps_id == 1
    encoder = dataclasses.replace(p.config.encoder, gps_id_from_autopilot=False)
    p.reconfigure(dataclasses.replace(p.config, encoder=encoder))
    assert p.encoder.gps_id == 0  # the configured id again
    assert p.decoder.gnss.injected_receiver is None  # GPS 2 is no longer fed by us
    assert not p.engine.autopilot_fuses_output


def test_streams_requested_on_a_heartbeat_before_any_time() -> None:
    """ArduCopter sends nothing timed on a port until asked: the first HEARTBEAT (no
    clock yet, no sample) must already bring the stream requests."""
    p = Pipeline()
    out = _msgs(p.on_message(AP.parsed(heartbeat(3)), 0.0))
    assert any(
        m.get_type() == "COMMAND_LONG" and m.command == MAV_CMD_SET_MESSAGE_INTERVAL for m in out
    )
    assert _msgs(p.on_message(AP.parsed(heartbeat(3)), 1.0)) == []  # once


def _fly_repeated_fixes(p: Pipeline, seconds: float) -> None:
    """ArduPlane's 10 Hz GPS_RAW_INT of a 5 Hz receiver: each fix sent twice."""
    for k in range(int(seconds * 10)):
        t_ms = 10_000 + 100 * k
        p.on_message(AP.parsed(attitude(t_ms)), 0.0)
        fix_ms = t_ms - t_ms % 200
        p.on_message(AP.parsed(gps_raw(fix_ms * 1000)), 0.0)


def test_gnss_rate_checked_against_the_receivers_rate(caplog: pytest.LogCaptureFixture) -> None:
    """Repeats are no fixes: 5 distinct fixes a second meet a 5 Hz receiver
    (GPS1_RATE_MS 200) asked for at 10 Hz, and fall short when its rate is unknown."""

    def gnss_warnings() -> list[str]:
        return [r.getMessage() for r in caplog.records if "stream rate: GNSS" in r.getMessage()]

    p, _ = _started()
    p.on_message(_param("GPS1_RATE_MS", 200.0), 0.1)
    with caplog.at_level(logging.WARNING, logger="companion.pipeline"):
        _fly_repeated_fixes(p, 30.0)
    assert p.decoder.rejections["repeated_fix"] > 100
    assert gnss_warnings() == []
    caplog.clear()
    q, _ = _started()
    with caplog.at_level(logging.WARNING, logger="companion.pipeline"):
        _fly_repeated_fixes(q, 30.0)
    (warning,) = gnss_warnings()
    assert warning.endswith("requested 10 Hz"), warning
