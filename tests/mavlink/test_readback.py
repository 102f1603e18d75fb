"""Reading back what the encoder published gives the outputs (to MAVLink's resolution)."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.encode import Encoder
from companion.mavlink.framing import FrameParser
from companion.mavlink.readback import (
    PublishedFix,
    PublishedHeartbeat,
    PublishedPosition,
    PublishedSensorFix,
    PublishedText,
    TextJoiner,
    from_service,
    parse_alert,
    read_message,
)
from companion.types import Alert, AlertCode, AutopilotFlavour, FixType, NamedValue, Severity
from tests.mavlink.test_encode import solution


def _published(frames: list[bytes]) -> list:
    msgs = FrameParser().feed(b"".join(frames))
    assert all(from_service(m) for m in msgs)
    return [read_message(m) for m in msgs]


def test_solution_reads_back() -> None:
    enc = Encoder()
    sol = solution()
    frames = [f for _, f in enc.encode_frames(sol, AutopilotFlavour.ARDUPILOT)]
    pos, fix = _published(frames)
    assert isinstance(pos, PublishedPosition) and isinstance(fix, PublishedFix)
    assert pos.t_s == pytest.approx(sol.t_s, abs=1e-3)
    assert pos.lat_rad == pytest.approx(sol.lat_rad, abs=1e-9)
    assert pos.lon_rad == pytest.approx(sol.lon_rad, abs=1e-9)
    assert pos.alt_msl_m == pytest.approx(sol.alt_msl_m, abs=1e-3)
    assert pos.vel_ned_mps == pytest.approx(tuple(sol.vel_ned_mps), abs=0.01)
    assert pos.yaw_rad == pytest.approx(sol.yaw_rad % (2.0 * math.pi), abs=1e-3)
    assert fix.fix_type == int(sol.fix_type)
    assert fix.h_acc_m == pytest.approx(sol.h_acc_m, rel=1e-6)
    assert fix.v_acc_m == pytest.approx(sol.v_acc_m, rel=1e-6)
    assert fix.t_s == pytest.approx(sol.t_s, abs=1e-6)
    assert (fix.lat_rad, fix.lon_rad) == (pos.lat_rad, pos.lon_rad)
    assert fix.alt_msl_m == pytest.approx(sol.alt_msl_m, abs=1e-4)
    assert fix.vel_ned_mps == pytest.approx(tuple(sol.vel_ned_mps), abs=1e-5)


def test_px4_solution_reads_back() -> None:
    enc = Encoder()
    for fix_type, healthy in ((FixType.FIX_3D, True), (FixType.FIX_2D, False)):
        frames = [f for _, f in enc.encode_frames(solution(fix=fix_type), AutopilotFlavour.PX4)]
        pos, sensor = _published(frames)
        assert isinstance(sensor, PublishedSensorFix) and sensor.healthy is healthy
        assert sensor.t_s == pytest.approx(pos.t_s, abs=1e-6)
        assert (sensor.lat_rad, sensor.lon_rad) == (pos.lat_rad, pos.lon_rad)
        assert sensor.h_acc_m == pytest.approx(0.8, rel=1e-6)
        assert sensor.v_acc_m == pytest.approx(1.5, rel=1e-6)


def test_unknown_yaw_alert_named_value_heartbeat() -> None:
    enc = Encoder()
    frames = [f for _, f in enc.encode_frames(solution(yaw=None), AutopilotFlavour.UNKNOWN)]
    alert = Alert(t_s=1.0, code=AlertCode.GNSS_LOST, severity=Severity.WARNING, text="no fix")
    frames += [f for _, f in enc.encode_frames(alert, AutopilotFlavour.UNKNOWN)]
    nv = NamedValue(t_s=2.5, name="CMP_HPL", value=12.5)
    frames += [f for _, f in enc.encode_frames(nv, AutopilotFlavour.UNKNOWN)]
    frames.append(enc.pack(enc.heartbeat(4)))
    pos, text, named, hb = _published(frames)
    assert isinstance(pos, PublishedPosition) and pos.yaw_rad is None
    assert text == PublishedText("CMP GNSS_LOST no fix", int(Severity.WARNING), 0)
    assert parse_alert(text.text) == ("GNSS_LOST", "no fix")
    assert named == nv
    assert hb == PublishedHeartbeat(system_status=4)


def test_other_messages_and_components() -> None:
    ack = apm.MAVLink_command_ack_message(31010, 0, 0, 0, 1, 1)
    assert read_message(ack) is None
    ap = apm.MAVLink(None, 1, 1)
    frame = apm.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3).pack(ap)
    hb = apm.MAVLink(None).decode(bytearray(frame))
    assert not from_service(hb)


def test_text_joiner_and_alert_parsing() -> None:
    joiner = TextJoiner()
    first = "A" * 50
    assert joiner.add("k0", PublishedText(first, 4, 7)) is None
    assert joiner.add("k1", PublishedText("tail", 6, 7)) == ("k0", first + "tail", 4)
    assert joiner.add("k2", PublishedText("whole", 5, 0)) == ("k2", "whole", 5)
    assert joiner.add("k3", PublishedText("B" * 50, 3, 9)) is None
    assert joiner.unfinished() == [("k3", "B" * 50, 3)]
    assert parse_alert("CMP ") is None and parse_alert("hello") is None
    assert parse_alert("CMP CAT none -> CAT III") == ("CAT", "none -> CAT III")
