"""The MAVLink command protocol at component 191, and the heading correction's state.

The bundled taxi (1 deg injected heading error) is replayed through the real pipeline;
a ground station (pymavlink, system 255 component 190) sends COMMAND_LONG and
COMMAND_INT and every command addressed to us must get exactly one COMMAND_ACK with
the result of the table in docs/mavlink.md. ``CMP_HDGS`` must follow the state and
each change must be announced by a STATUSTEXT.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.config import Config, load_config
from companion.mavlink.ids import (
    MAV_COMP_ID_ONBOARD_COMPUTER,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
)
from companion.mavlink.readback import PublishedText, TextJoiner
from companion.mavlink.tlog import TlogReader
from companion.mavlink.units import CDEG_PER_RAD
from companion.nav.heading import HeadingStatus
from companion.pipeline import Pipeline
from tests.helpers import TAXI, TAXI_HEADING_ERROR_DEG

ROOT = Path(__file__).resolve().parent.parent
HEADING = 31010
GCS_SYS, GCS_COMP = 255, 190

# codes of the STATUSTEXTs announcing each status (CMP_HDGS value)
ANNOUNCES = {
    HeadingStatus.IDLE: {"HDG_IDLE"},
    HeadingStatus.ACCUMULATING: {"HDG_ACCUM"},
    HeadingStatus.READY: {"HDG_READY", "HDG_UNDONE"},
    HeadingStatus.APPLIED: {"HDG_APPLIED"},
    HeadingStatus.REJECTED: {"HDG_REJECT"},
}


@pytest.fixture(scope="module")
def taxi() -> list[tuple[float, Any]]:
    return list(TlogReader(TAXI))


@pytest.fixture(scope="module")
def milestones(taxi) -> tuple[int, int]:
    """Indices of the taxi messages after which the correction is ACCUMULATING (half-way
    between its first cycle and READY), and READY."""
    pipeline = Pipeline()
    first = None
    for k, (t, msg) in enumerate(taxi):
        pipeline.on_message(msg, t)
        got = pipeline.engine.heading.status
        if first is None and got is HeadingStatus.ACCUMULATING:
            first = k + 1
        if got is HeadingStatus.READY:
            assert first is not None
            return (first + k + 1) // 2, k + 1
    raise AssertionError("the taxi never became READY")


@pytest.fixture(scope="module")
def ready_at(milestones) -> int:
    return milestones[1]


@pytest.fixture(scope="module")
def accumulating_at(milestones) -> int:
    return milestones[0]


@dataclass
class Gcs:
    """A ground station talking to one pipeline: it sends commands, parses what comes back."""

    pipeline: Pipeline
    t_rx_s: float
    mav: Any = field(default_factory=lambda: apm.MAVLink(None, GCS_SYS, GCS_COMP))
    rx: Any = field(default_factory=lambda: apm.MAVLink(None))
    hdgs: list[float] = field(default_factory=list)
    texts: list[str] = field(default_factory=list)

    def parse(self, frames: list[bytes]) -> list[Any]:
        msgs = [self.rx.decode(bytearray(f)) for f in frames]
        for m in msgs:
            if m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "CMP_HDGS":
                self.hdgs.append(m.value)
            elif m.get_type() == "STATUSTEXT":
                self.texts.append(m.text)
        return msgs

    def feed(self, messages: list[tuple[float, Any]]) -> list[Any]:
        out = []
        for t, msg in messages:
            out += self.parse(self.pipeline.on_message(msg, t))
            self.t_rx_s = t
        return out

    def send(
        self,
        param1: float,
        *,
        command: int = HEADING,
        confirmation: int = 0,
        kind: str = "long",
        target_system: int = 1,
        target_component: int = MAV_COMP_ID_ONBOARD_COMPUTER,
    ) -> list[Any]:
        if kind == "long":
            msg = apm.MAVLink_command_long_message(
                target_system, target_component, command, confirmation, param1, 0, 0, 0, 0, 0, 0
            )
        else:
            msg = apm.MAVLink_command_int_message(
                target_system, target_component, 0, command, 0, 0, param1, 0, 0, 0, 0, 0, 0
            )
        parsed = self.rx.decode(bytearray(msg.pack(self.mav)))
        self.mav.seq = (self.mav.seq + 1) % 256
        self.t_rx_s += 0.05
        return self.parse(self.pipeline.on_message(parsed, self.t_rx_s))


def acks(msgs: list[Any]) -> list[Any]:
    return [m for m in msgs if m.get_type() == "COMMAND_ACK"]


def texts(msgs: list[Any]) -> list[str]:
    """The whole texts (a long one's chunks joined)."""
    joiner = TextJoiner()
    done = [
        joiner.add(0, PublishedText(m.text, m.severity, m.id))
        for m in msgs
        if m.get_type() == "STATUSTEXT"
    ]
    return [text for _, text, _ in filter(None, done)]


def codes(msgs: list[Any]) -> list[str]:
    return [t.split()[1] for t in texts(msgs)]


def one_ack(msgs: list[Any], command: int = HEADING) -> int:
    """The result of the one COMMAND_ACK in ``msgs``, checked to answer the GCS from 191."""
    got = acks(msgs)
    assert len(got) == 1, f"{len(got)} COMMAND_ACKs"
    ack = got[0]
    assert ack.command == command
    assert (ack.target_system, ack.target_component) == (GCS_SYS, GCS_COMP)
    assert ack.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER
    return int(ack.result)


def status(gcs: Gcs) -> HeadingStatus:
    return gcs.pipeline.engine.heading.status


# ----------------------------------------------------------------------------- the table


def test_every_heading_command_case_gets_exactly_one_ack(taxi, accumulating_at, ready_at):
    gcs = Gcs(Pipeline(), 0.0)
    gcs.feed(taxi[:accumulating_at])
    heading = gcs.pipeline.engine.heading
    assert status(gcs) is HeadingStatus.ACCUMULATING

    # (param1, send kwargs, result, STATUSTEXT codes, status after)
    A, T, D = MAV_RESULT_ACCEPTED, MAV_RESULT_TEMPORARILY_REJECTED, MAV_RESULT_DENIED
    while_accumulating = [
        (1, {}, T, ["HDG_CMD"], HeadingStatus.ACCUMULATING),  # nothing ready
        (2, {}, D, ["HDG_CMD"], HeadingStatus.ACCUMULATING),  # nothing applied
        (0, {}, A, [], HeadingStatus.ACCUMULATING),  # nothing to refuse: no change
        (3, {}, D, ["HDG_CMD"], HeadingStatus.ACCUMULATING),  # not a value of param1
        (0.5, {}, D, ["HDG_CMD"], HeadingStatus.ACCUMULATING),
        (math.nan, {}, D, ["HDG_CMD"], HeadingStatus.ACCUMULATING),
        (1, {"kind": "int"}, T, ["HDG_CMD"], HeadingStatus.ACCUMULATING),
    ]
    when_ready = [
        (2, {}, D, ["HDG_CMD"], HeadingStatus.READY),  # undo: nothing applied
        (1, {"kind": "int"}, A, ["HDG_APPLIED"], HeadingStatus.APPLIED),  # confirm
        (1, {}, A, [], HeadingStatus.APPLIED),  # confirm again: idempotent
        (1, {"confirmation": 1}, A, [], HeadingStatus.APPLIED),  # its retransmission
        (0, {}, D, ["HDG_CMD"], HeadingStatus.APPLIED),  # refuse an applied one: undo it
        (2, {}, A, ["HDG_UNDONE"], HeadingStatus.READY),  # undo
        (2, {"confirmation": 1}, A, [], HeadingStatus.READY),  # its retransmission
        (2, {"confirmation": 2}, A, [], HeadingStatus.READY),  # and another
        (2, {}, D, ["HDG_CMD"], HeadingStatus.READY),  # a new undo: nothing applied
        (2, {"confirmation": 1}, D, ["HDG_CMD"], HeadingStatus.READY),  # and its retransmission
        (1, {}, A, ["HDG_APPLIED"], HeadingStatus.APPLIED),  # confirm again, announced
        (2, {"kind": "int"}, A, ["HDG_UNDONE"], HeadingStatus.READY),  # undo again
        (0, {}, A, ["HDG_REJECT"], HeadingStatus.REJECTED),  # refuse when ready
        (0, {"confirmation": 1}, A, [], HeadingStatus.REJECTED),  # its retransmission
        (1, {}, T, ["HDG_CMD"], HeadingStatus.REJECTED),  # nothing ready now
        (2, {}, D, ["HDG_CMD"], HeadingStatus.REJECTED),
    ]
    for step, (p1, kwargs, result, want_codes, after) in enumerate(while_accumulating):
        msgs = gcs.send(p1, **kwargs)
        assert one_ack(msgs) == result, (step, p1, kwargs)
        assert codes(msgs) == want_codes, (step, p1, kwargs, texts(msgs))
        assert status(gcs) is after, (step, p1, kwargs)
    assert heading.correction_rad == 0.0

    gcs.feed(taxi[accumulating_at:ready_at])
    assert status(gcs) is HeadingStatus.READY
    candidate = heading.candidate
    assert candidate is not None
    for step, (p1, kwargs, result, want_codes, after) in enumerate(when_ready):
        msgs = gcs.send(p1, **kwargs)
        assert one_ack(msgs) == result, (step, p1, kwargs)
        assert codes(msgs) == want_codes, (step, p1, kwargs, texts(msgs))
        assert status(gcs) is after, (step, p1, kwargs)
        applied = after is HeadingStatus.APPLIED
        assert heading.correction_rad == (candidate.correction_rad if applied else 0.0)

    # the reasons say what to do
    reasons = [t for t in gcs.texts if t.startswith("CMP HDG_CMD")]
    assert "CMP HDG_CMD confirm: none ready (accumulating)" in reasons
    assert "CMP HDG_CMD refuse: applied; undo it instead" in reasons
    assert "CMP HDG_CMD param1 3: 0 refuse, 1 confirm, 2 undo" in reasons
    assert all(len(t) <= 50 for t in gcs.texts)
    stats = gcs.pipeline.stats.commands
    assert sum(stats.values()) == len(while_accumulating) + len(when_ready)
    assert gcs.pipeline.retransmissions.repeated == 4
    rejections = gcs.pipeline.decoder.rejections
    assert rejections["bad_command_param"] == 3


def test_other_commands(taxi):
    gcs = Gcs(Pipeline(), 0.0)
    gcs.feed(taxi[:2000])
    # a command we do not implement, addressed to us: UNSUPPORTED, in either message
    for kind in ("long", "int"):
        msgs = gcs.send(33, command=512, kind=kind)
        assert one_ack(msgs, 512) == MAV_RESULT_UNSUPPORTED
        assert texts(msgs) == []
    # broadcast, it is answered by the component that implements it; to another
    # component or system it is not ours at all
    for target in ({"target_component": 0}, {"target_component": 1}, {"target_system": 7}):
        assert acks(gcs.send(33, command=512, **target)) == []
    assert acks(gcs.send(1, target_component=1)) == []
    assert acks(gcs.send(1, target_system=7)) == []
    # the heading command broadcast is ours: answered
    assert one_ack(gcs.send(1, target_system=0, target_component=0)) == (
        MAV_RESULT_TEMPORARILY_REJECTED
    )
    assert gcs.pipeline.decoder.rejections["unsupported_command"] == 2


def test_a_command_before_the_autopilot_clock_is_temporarily_rejected():
    gcs = Gcs(Pipeline(), 0.0)
    msgs = gcs.send(1, target_system=0)
    assert one_ack(msgs) == MAV_RESULT_TEMPORARILY_REJECTED
    assert texts(msgs) == ["CMP HDG_CMD no autopilot clock yet"]


def test_a_command_that_fails_is_answered_failed_and_the_service_carries_on(taxi, monkeypatch):
    gcs = Gcs(Pipeline(), 0.0)
    gcs.feed(taxi[:2000])

    def broken(command):
        raise RuntimeError("injected")

    monkeypatch.setattr(gcs.pipeline.engine.heading, "on_command", broken)
    msgs = gcs.send(1)
    assert one_ack(msgs) == MAV_RESULT_FAILED
    assert codes(msgs) == ["HDG_CMD"]
    monkeypatch.undo()
    assert one_ack(gcs.send(1)) == MAV_RESULT_TEMPORARILY_REJECTED
    assert any(m.get_type() == "GLOBAL_POSITION_INT" for m in gcs.feed(taxi[2000:2200]))


# ----------------------------------------------------------------------------- undo


def _yaw_deg(x: float) -> float:
    return (math.degrees(x) + 180.0) % 360.0 - 180.0


def _wrap_deg(x: float) -> float:
    return (x + 180.0) % 360.0 - 180.0


def _truth():
    return np.genfromtxt(
        TAXI.with_suffix("").with_suffix(".truth.csv"),
        delimiter=",",
        names=True,
        dtype=None,
        encoding="utf-8",
    )


def _heading_errors_deg(msgs: list[Any], min_speed_mps: float) -> list[tuple[float, float]]:
    """(time, published heading - true heading) of the GLOBAL_POSITION_INTs, the truth
    (10 Hz) interpolated to their time, on straight taxi (truth turning under 1 deg/s),
    deg."""
    truth = _truth()
    out = []
    for m in msgs:
        if m.get_type() != "GLOBAL_POSITION_INT" or m.hdg == 65535:
            continue
        if math.hypot(m.vx, m.vy) / 100 < min_speed_mps:
            continue
        t = m.time_boot_ms / 1000
        k = int(np.searchsorted(truth["t_s"], t))
        if not 0 < k < len(truth):
            continue
        t0, t1 = truth["t_s"][k - 1], truth["t_s"][k]
        turn_deg = _wrap_deg(truth["yaw_deg"][k] - truth["yaw_deg"][k - 1])
        if abs(turn_deg) / (t1 - t0) > 1.0:
            continue
        yaw_deg = truth["yaw_deg"][k - 1] + turn_deg * (t - t0) / (t1 - t0)
        err = _wrap_deg(m.hdg / CDEG_PER_RAD * 180 / math.pi - yaw_deg)
        out.append((t, err))
    return out


@pytest.mark.parametrize("config", ["default", "tactical"])
def test_undo_returns_every_estimator_to_the_uncorrected_heading(taxi, ready_at, config):
    """Confirm, then undo: at once the blend (attitude-aided by default, strapdown with
    the tactical configuration), the inertial references (tactical) and the published
    heading follow the autopilot's own heading again, 1 deg off the truth; from then on
    the blend refines it from GNSS as it does when nothing was applied."""
    cfg = load_config(ROOT / "sitl_fixtures" / "tactical.toml") if config == "tactical" else None
    gcs = Gcs(Pipeline(cfg), 0.0)
    gcs.feed(taxi[:ready_at])
    engine = gcs.pipeline.engine

    def autopilot_yaw_deg(upto: int) -> float:
        return _yaw_deg([m.yaw for _, m in taxi[:upto] if m.get_type() == "ATTITUDE"][-1])

    def blend_yaw_deg() -> float:
        blend = engine.navigators.primary
        state = blend.predict(blend.imu_t_s)
        return _yaw_deg(state.yaw_rad)

    def coast_yaw_deg() -> float:
        att = engine.coast._att
        return math.degrees(math.atan2(att[3], att[0]))

    assert one_ack(gcs.send(1)) == MAV_RESULT_ACCEPTED
    correction_deg = math.degrees(engine.heading.correction_rad)
    assert correction_deg == pytest.approx(TAXI_HEADING_ERROR_DEG, abs=0.1)
    # at once: every estimator uses the corrected heading
    corrected = autopilot_yaw_deg(ready_at) - correction_deg
    assert _wrap_deg(blend_yaw_deg() - corrected) == pytest.approx(0.0, abs=0.05)
    if config == "tactical":
        assert _wrap_deg(coast_yaw_deg() - corrected) == pytest.approx(0.0, abs=1e-9)
    half = (ready_at + len(taxi)) // 2
    before = gcs.feed(taxi[ready_at:half])

    msgs = gcs.send(2)
    assert one_ack(msgs) == MAV_RESULT_ACCEPTED and codes(msgs) == ["HDG_UNDONE"]
    assert engine.heading.correction_rad == 0.0
    # at once: the uncorrected heading again
    uncorrected = autopilot_yaw_deg(half)
    assert _wrap_deg(blend_yaw_deg() - uncorrected) == pytest.approx(0.0, abs=0.05)
    if config == "tactical":
        assert _wrap_deg(coast_yaw_deg() - uncorrected) == pytest.approx(0.0, abs=1e-9)
    t_undo_s = engine.now_s
    after = gcs.feed(taxi[half:])

    # published, against the truth on the straight: corrected the second before the undo,
    # the autopilot's error the second after it
    last_applied = [e for t, e in _heading_errors_deg(before, 1.0) if t > t_undo_s - 1.0]
    first_undone = [e for t, e in _heading_errors_deg(after, 1.0) if t < t_undo_s + 1.0]
    assert len(last_applied) >= 3 and len(first_undone) >= 3
    assert np.mean(last_applied) == pytest.approx(0.0, abs=0.1)
    assert np.mean(first_undone) == pytest.approx(TAXI_HEADING_ERROR_DEG, abs=0.1)
    assert gcs.hdgs[-1] == HeadingStatus.READY  # the candidate, to confirm again or refuse


def test_the_strapdown_blend_takes_the_corrected_heading_when_applied(taxi):
    """With the tactical configuration (strapdown blend) the applied correction removes
    the heading error: the blend restarts its heading from the corrected autopilot
    heading, not from the heading before the correction."""
    cfg = load_config(ROOT / "sitl_fixtures" / "tactical.toml")
    cfg = replace(cfg, heading=replace(cfg.heading, auto_apply=True))
    gcs = Gcs(Pipeline(cfg), 0.0)
    out = gcs.feed(taxi)
    applied_at = next(
        m.time_boot_ms / 1000
        for m in out
        if m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "CMP_HDGS" and m.value == 3
    )
    after = [e for t, e in _heading_errors_deg(out, 3.0) if t > applied_at]
    assert len(after) > 100
    assert abs(np.mean(after)) < 0.05, np.mean(after)


# ----------------------------------------------------------------------------- the state


def test_the_state_is_published_and_every_change_announced(taxi, ready_at):
    gcs = Gcs(Pipeline(), 0.0)
    seen = []  # (CMP_HDGS value, STATUSTEXT codes since the previous value)
    pending: list[str] = []

    def watch(msgs):
        for m in msgs:
            if m.get_type() == "STATUSTEXT" and m.text.startswith("CMP HDG_"):
                pending.append(m.text.split()[1])
            elif m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "CMP_HDGS":
                seen.append((HeadingStatus(int(m.value)), list(pending)))
                pending.clear()

    for k in range(0, ready_at + 300, 500):
        watch(gcs.feed(taxi[k : min(k + 500, ready_at + 300)]))
    watch(gcs.send(1))
    watch(gcs.feed(taxi[ready_at + 300 : ready_at + 2000]))
    watch(gcs.send(2))
    watch(gcs.feed(taxi[ready_at + 2000 : ready_at + 4000]))
    watch(gcs.send(0))
    watch(gcs.feed(taxi[ready_at + 4000 : ready_at + 6000]))
    values = [v for v, _ in seen]
    assert len(values) > 60  # at the status rate (1 Hz of autopilot time)
    changes = [(b, why) for (a, _), (b, why) in zip(seen, seen[1:], strict=False) if a is not b]
    order = [b for b, _ in changes]
    assert order[:5] == [
        HeadingStatus.ACCUMULATING,
        HeadingStatus.READY,
        HeadingStatus.APPLIED,
        HeadingStatus.READY,
        HeadingStatus.REJECTED,
    ]
    assert values[0] is HeadingStatus.IDLE
    for value, why in changes:
        assert set(why) & ANNOUNCES[value], (value, why)


def test_in_air_alone_does_not_end_the_taxi(taxi, accumulating_at):
    """ArduPlane says "in air" as soon as it rolls: without motion evidence of flight
    (speed, height, climb, pitch) the taxi goes on (a real take-off ending the
    accumulation: tests/nav/test_heading_ground.py)."""
    gcs = Gcs(Pipeline(), 0.0)
    gcs.feed(taxi[:accumulating_at])
    assert status(gcs) is HeadingStatus.ACCUMULATING
    autopilot = apm.MAVLink(None, 1, 1)
    in_air = apm.MAVLink_extended_sys_state_message(0, 2)
    parsed = gcs.rx.decode(bytearray(in_air.pack(autopilot)))
    msgs = gcs.parse(gcs.pipeline.on_message(parsed, gcs.t_rx_s))
    assert texts(msgs) == []
    n_before = gcs.pipeline.engine.heading.estimate().n
    gcs.feed(taxi[accumulating_at : accumulating_at + 300])
    assert not gcs.pipeline.engine.heading.airborne
    assert gcs.hdgs[-1] == HeadingStatus.ACCUMULATING
    assert gcs.pipeline.engine.heading.estimate().n > n_before


def test_a_restored_correction_is_announced(taxi, ready_at):
    first = Gcs(Pipeline(), 0.0)
    first.feed(taxi[:ready_at])
    assert one_ack(first.send(1)) == MAV_RESULT_ACCEPTED
    saved = json.loads(json.dumps(first.pipeline.engine.persistent_state()))
    applied = first.pipeline.engine.heading.correction_rad
    estimate = first.pipeline.engine.heading.applied
    assert estimate is not None
    value = f"{math.degrees(applied):.2f} +/-{math.degrees(estimate.eps_rad):.2f} n={estimate.n}"

    second = Gcs(Pipeline(Config()), 0.0)
    second.pipeline.engine.restore(saved)
    out = second.feed(taxi[ready_at : ready_at + 100])
    restored = [t for t in texts(out) if t.startswith("CMP HDG_RESTORED")]
    assert restored == [f"CMP HDG_RESTORED applied {value}"]
    assert second.pipeline.engine.heading.correction_rad == applied
    # the restored correction answers as the original would
    assert one_ack(second.send(1)) == MAV_RESULT_ACCEPTED
    assert one_ack(second.send(2)) == MAV_RESULT_ACCEPTED
    assert second.pipeline.engine.heading.correction_rad == 0.0
