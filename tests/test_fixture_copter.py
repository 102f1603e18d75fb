"""The realistic simulated copter (sitl_fixtures/copter_realistic: ArduCopter's 50 Hz
RAW_IMU carrying aliased rotor vibration about 100 times the MEMS density, an RTK
receiver whose velocity has a slowly varying bias): the blend keeps the receiver's
fixes, and no alert claims a fault the flight does not have."""

from __future__ import annotations

import json
from pathlib import Path

from companion.config import Config
from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.tlog import TlogReader
from companion.pipeline import Pipeline
from companion.types import AlertCode

FIXTURES = Path(__file__).resolve().parent.parent / "sitl_fixtures"


def test_a_vibrating_copter_keeps_its_receiver_without_false_faults() -> None:
    pipeline = Pipeline(Config())
    for t_rx_s, msg in TlogReader(FIXTURES / "copter_realistic.tlog", light_ids=LIGHT_MESSAGE_IDS):
        pipeline.on_message(msg, t_rx_s)
    events = json.loads((FIXTURES / "copter_realistic.json").read_text())["events"]
    assert not [e for e in events if e["kind"] in ("step", "ramp", "dither")]
    gnss = pipeline.engine.stats.gnss
    # with the datasheet density in its noise model the blend gated 277 of the fixes and
    # was reset to the receiver 101 times, 4 of them alerted as faults
    assert gnss["gate_rejected"] <= 10, gnss
    assert gnss["reinitialised"] <= 3, gnss
    assert not [a for a in pipeline.alerts if a.code is AlertCode.FAULT]
