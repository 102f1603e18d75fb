"""PX4's aux global position set-up: the GLOBAL_POSITION_SENSOR id read from EKF2_AGP0_ID,
the fusion switched off said in a STATUSTEXT."""

from __future__ import annotations

import struct
from dataclasses import replace
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.config import Config
from companion.mavlink.encode import EncoderConfig
from companion.mavlink.px4_agp import RETRY_S, Px4AgpSetup, px4_int
from companion.pipeline import Pipeline
from companion.types import AutopilotFlavour, FixType, NavMode
from tests.mavlink._util import Packer, attitude, heartbeat
from tests.mavlink.test_encode import solution

MAV_AUTOPILOT_PX4 = 12


def _frames(frames: list[bytes]) -> list[Any]:
    rx = apm.MAVLink(None)
    return [rx.decode(bytearray(f)) for f in frames]


def _param(pk: Packer, name: str, value: int) -> Any:
    """A PARAM_VALUE as PX4 sends an INT32: bytewise in the float."""
    as_float = struct.unpack("<f", struct.pack("<i", value))[0]
    return pk.parsed(apm.MAVLink_param_value_message(name.encode(), as_float, 6, 900, 0))


def test_px4_int_bytewise_and_real() -> None:
    one = struct.unpack("<f", struct.pack("<i", 1))[0]
    assert px4_int(one, 6) == 1
    assert px4_int(3.0, 9) == 3
    assert px4_int(2.5, 9) is None


def _meet(pipeline: Pipeline, pk: Packer, autopilot: int) -> list[bytes]:
    """The autopilot's heartbeat (its system), a clock (ATTITUDE), a heartbeat again."""
    frames = pipeline.on_message(pk.parsed(heartbeat(autopilot=autopilot)), 0.8)
    frames += pipeline.on_message(pk.parsed(attitude(1000)), 0.9)
    return frames + pipeline.on_message(pk.parsed(heartbeat(autopilot=autopilot)), 1.0)


def _pipeline_on_px4(gps_id: int = 0) -> tuple[Pipeline, Packer, list[Any]]:
    pipeline = Pipeline(Config(encoder=EncoderConfig(gps_id=gps_id)))
    pk = Packer()
    out = _frames(_meet(pipeline, pk, MAV_AUTOPILOT_PX4))
    return pipeline, pk, out


def test_px4_parameters_are_asked_for_and_set_the_id() -> None:
    pipeline, pk, out = _pipeline_on_px4()
    reads = [m for m in out if m.get_type() == "PARAM_REQUEST_READ"]
    assert sorted(m.param_id for m in reads) == ["EKF2_AGP0_CTRL", "EKF2_AGP0_ID"]
    assert all(m.target_system == 1 and m.target_component == 1 for m in reads)
    assert _frames(pipeline.on_message(_param(pk, "EKF2_AGP0_ID", 7), 1.1)) == []
    assert _frames(pipeline.on_message(_param(pk, "EKF2_AGP0_CTRL", 1), 1.2)) == []
    assert pipeline.encoder.agp_id == 7
    assert pipeline.decoder.accepted["PARAM_VALUE"] == 2
    _, gps = pipeline.encoder.encode(solution(), AutopilotFlavour.PX4)
    assert gps.get_type() == "GLOBAL_POSITION_SENSOR" and gps.id == 7


def test_fusion_off_and_id_mismatch_are_announced() -> None:
    pipeline, pk, _ = _pipeline_on_px4(gps_id=3)
    pipeline.on_message(_param(pk, "EKF2_AGP0_ID", 1), 1.1)
    out = _frames(pipeline.on_message(_param(pk, "EKF2_AGP0_CTRL", 0), 1.2))
    texts = [m.text for m in out if m.get_type() == "STATUSTEXT"]
    assert len(texts) >= 1 and texts[0].startswith("CMP AP_CONFIG")
    text = "".join(texts)
    assert "EKF2_AGP0_CTRL=0" in text and "gps_id 3" in text
    assert pipeline.encoder.agp_id == 1


def test_ardupilot_is_not_asked() -> None:
    pipeline, pk = Pipeline(), Packer()
    out = _frames(_meet(pipeline, pk, 3))
    assert [m for m in out if m.get_type() == "COMMAND_LONG"]
    names = {m.param_id for m in out if m.get_type() == "PARAM_REQUEST_READ"}
    assert not names & {"EKF2_AGP0_ID", "EKF2_AGP0_CTRL"}


def test_requests_are_repeated_until_answered() -> None:
    setup = Px4AgpSetup(0)
    assert len(setup.requests(apm, (1, 1), None)) == 2
    assert setup.requests(apm, (1, 1), 1.0) == []  # the retry clock starts
    assert setup.requests(apm, (1, 1), 0.99 + RETRY_S) == []
    assert len(setup.requests(apm, (1, 1), 1.0 + RETRY_S)) == 2
    assert setup.requests(apm, (1, 1), 1.5 + RETRY_S) == []


def test_nothing_goes_to_px4_before_its_id_is_read_then_the_configured_id() -> None:
    """A GLOBAL_POSITION_SENSOR of another id sent first kept PX4 SIH from ever fusing the
    right one: none is sent while the parameters are read; unanswered, the configured id."""
    pipeline, pk, _ = _pipeline_on_px4(gps_id=4)
    assert pipeline.encoder.agp_hold
    assert len(pipeline.encoder.encode(solution(), AutopilotFlavour.PX4)) == 1  # GPI only
    for k in range(40):  # the autopilot's clock runs, no answer comes
        pipeline.on_message(pk.parsed(attitude(2000 + 1000 * k)), 2.0 + k)
    assert not pipeline.encoder.agp_hold
    _, gps = pipeline.encoder.encode(solution(), AutopilotFlavour.PX4)
    assert gps.id == 4


def test_no_feed_to_px4_from_a_gap_until_gnss_is_trusted() -> None:
    """Fusion on: bridged or reacquiring, the solution rests on PX4's own attitude and IMU;
    PX4 does not get it back. The ground station still does (GLOBAL_POSITION_INT)."""
    pipeline, pk, _ = _pipeline_on_px4()
    pipeline.on_message(_param(pk, "EKF2_AGP0_ID", 2), 1.1)
    pipeline.on_message(_param(pk, "EKF2_AGP0_CTRL", 1), 1.2)
    enc = pipeline.encoder
    assert enc.feedback_guard
    for mode in (NavMode.BRIDGING, NavMode.LOST, NavMode.REACQUIRING):
        msgs = enc.encode(replace(solution(), mode=mode), AutopilotFlavour.PX4)
        assert [m.get_type() for m in msgs] == ["GLOBAL_POSITION_INT"]
    for mode in (NavMode.NORMAL, NavMode.DEGRADED):
        msgs = enc.encode(replace(solution(), mode=mode), AutopilotFlavour.PX4)
        assert [m.get_type() for m in msgs] == ["GLOBAL_POSITION_INT", "GLOBAL_POSITION_SENSOR"]
    assert enc.held["feedback_guard"] == 3
    # PX4 ignores the flags: a solution without a fix is never sent to it
    msgs = enc.encode(replace(solution(), fix_type=FixType.NO_GPS), AutopilotFlavour.PX4)
    assert [m.get_type() for m in msgs] == ["GLOBAL_POSITION_INT"]
    assert enc.held["no_fix"] == 1
    # fusion off: PX4 ignores it, nothing to guard (and it is said: CMP AP_CONFIG)
    off, pk2, _ = _pipeline_on_px4()
    off.on_message(_param(pk2, "EKF2_AGP0_ID", 2), 1.1)
    off.on_message(_param(pk2, "EKF2_AGP0_CTRL", 0), 1.2)
    assert not off.encoder.feedback_guard
