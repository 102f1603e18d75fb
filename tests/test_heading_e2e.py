"""Taxi heading correction end to end: the bundled taxi (1 deg injected error)
replayed through the pipeline, the confirmation command, and a service restart."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.config import Config
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.tlog import TlogReader
from companion.mavlink.units import CDEG_PER_RAD
from companion.pipeline import Pipeline
from companion.types import AlertCode
from tests.helpers import TAXI, TAXI_HEADING_ERROR_DEG


@pytest.fixture(scope="module")
def taxi_messages():
    return list(TlogReader(TAXI))


def run(pipeline, messages):
    out = []
    for t, msg in messages:
        for frame in pipeline.on_message(msg, t):
            out.append(frame)
    return out


def parse(frames):
    mav = apm.MAVLink(None)
    return [mav.decode(bytearray(f)) for f in frames]


def alert_codes(pipeline):
    return [a.code for a in pipeline.alerts]


def test_taxi_replay_reaches_ready_within_a_tenth_of_a_degree(taxi_messages):
    pipeline = Pipeline()
    run(pipeline, taxi_messages)
    ready = [a for a in pipeline.alerts if a.code is AlertCode.HDG_READY]
    assert len(ready) == 1
    value_deg = float(ready[0].text.split()[0])
    assert abs(value_deg - TAXI_HEADING_ERROR_DEG) < 0.1
    # not applied without confirmation (auto_apply is off by default)
    assert pipeline.engine.heading.correction_rad == 0.0


def test_published_heading_is_corrected_against_truth(taxi_messages):
    """Before the correction GLOBAL_POSITION_INT.hdg carries most of the autopilot's
    ~1 deg error; after HDG_APPLIED it agrees with the true heading to well under 0.1 deg
    on straight taxi. (In turns at ~6 deg/s the published heading lags the truth by up
    to ~0.26 deg, about 45 ms: a known, open timing issue of the blend in turns.)"""
    cfg = Config()
    cfg = replace(cfg, heading=replace(cfg.heading, auto_apply=True))
    pipeline = Pipeline(cfg)
    frames = run(pipeline, taxi_messages)
    applied_at = next(a.t_s for a in pipeline.alerts if a.code is AlertCode.HDG_APPLIED)
    truth = np.genfromtxt(
        TAXI.with_suffix("").with_suffix(".truth.csv"),
        delimiter=",",
        names=True,
        dtype=None,
        encoding="utf-8",
    )
    before, after = [], []
    for m in parse(frames):
        if m.get_type() != "GLOBAL_POSITION_INT" or m.hdg == 65535:
            continue
        t = m.time_boot_ms / 1000
        speed = math.hypot(m.vx, m.vy) / 100
        if speed < 3.0:  # parked or turning slowly: heading still, but skip the stand
            continue
        k = int(np.searchsorted(truth["t_s"], t))
        if not 0 < k < len(truth):
            continue
        # the truth (10 Hz) interpolated to the publication's time (on each fix)
        t0, t1 = truth["t_s"][k - 1], truth["t_s"][k]
        turn_deg = (truth["yaw_deg"][k] - truth["yaw_deg"][k - 1] + 180) % 360 - 180
        # straight taxi only (the criterion of Markelov et al.); see the note below
        if abs(turn_deg) / (t1 - t0) > 1.0:
            continue
        yaw_deg = truth["yaw_deg"][k - 1] + turn_deg * (t - t0) / (t1 - t0)
        err = ((m.hdg / CDEG_PER_RAD) * 180 / math.pi - yaw_deg + 180) % 360 - 180
        (after if t > applied_at + 1.0 else before).append(err)
    assert len(before) > 100 and len(after) > 100
    # before: the blend's own heading (the autopilot's, partly refined by GNSS in the
    # taxi's turns) is still most of a degree off
    assert np.mean(before) > 0.5 * TAXI_HEADING_ERROR_DEG
    print(f"heading error before {np.mean(before):.3f} deg, after {np.mean(after):.3f} deg")
    assert abs(np.mean(after)) < 0.05
    assert np.max(np.abs(after)) < 0.2


def test_confirmation_command_applies_and_is_acknowledged(taxi_messages):
    pipeline = Pipeline()
    run(pipeline, taxi_messages)
    gcs = apm.MAVLink(None, 255, 190)
    cmd = apm.MAVLink_command_long_message(1, 191, 31010, 0, 1, 0, 0, 0, 0, 0, 0)
    parsed = apm.MAVLink(None).decode(bytearray(cmd.pack(gcs)))
    frames = pipeline.on_message(parsed, taxi_messages[-1][0] + 0.1)
    msgs = parse(frames)
    acks = [m for m in msgs if m.get_type() == "COMMAND_ACK"]
    assert len(acks) == 1 and acks[0].result == 0 and acks[0].command == 31010
    assert acks[0].target_system == 255
    assert all(m.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER for m in msgs)
    assert AlertCode.HDG_APPLIED in alert_codes(pipeline)
    assert pipeline.engine.heading.correction_rad == pytest.approx(
        math.radians(TAXI_HEADING_ERROR_DEG), abs=math.radians(0.1)
    )


def test_correction_survives_a_service_restart_but_not_an_autopilot_reboot(taxi_messages):
    cfg = Config()
    cfg = replace(cfg, heading=replace(cfg.heading, auto_apply=True))
    first = Pipeline(cfg)
    k = 0
    while AlertCode.HDG_APPLIED not in alert_codes(first):
        first.on_message(taxi_messages[k][1], taxi_messages[k][0])
        k += 1
    saved = json.loads(json.dumps(first.engine.persistent_state()))
    correction = first.engine.heading.correction_rad
    assert correction != 0.0

    # the service restarts during the same boot: the rest of the flight keeps the correction
    second = Pipeline(cfg)
    second.engine.restore(saved)
    run(second, taxi_messages[k:])
    assert second.engine.heading.correction_rad == correction
    assert AlertCode.HDG_APPLIED not in alert_codes(second)

    # the autopilot rebooted (its clock is behind the saved time): not restored
    third = Pipeline(cfg)
    third.engine.restore(saved)
    run(third, taxi_messages[:2000])
    assert third.engine.heading.correction_rad == 0.0
