"""The blend's start on a parked vehicle whose receiver's velocity is biased beyond its
report (companion.nav.blend.rest): the receiver is not excluded as faulty for the
prediction the biased velocity drags off its RTK fixes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

import companion.sim as sim
from companion.config import Config
from companion.replay import replay
from companion.sim.realism import realistic
from companion.sim.writer import write_tlog
from companion.types import AlertCode


@pytest.mark.parametrize("seed", [1, 2])
def test_a_parked_copter_with_a_biased_velocity_keeps_its_receiver(tmp_path: Path, seed) -> None:
    """A realistic ArduCopter parked 40 s, RTK fixed, its GNSS velocity off by a slowly
    varying 0.15 m/s (1-sigma per axis) while it reports 2 cm/s: no FAULT while parked
    (the blend fused the biased velocity as reported from its first fix and the receiver
    was excluded within a second: chi2 47.6 and 66.0 for these seeds)."""
    over = {k: v for k, v in realistic("copter").items() if k != "gnss_mode"}
    rl = dataclasses.replace(
        over["realism"], gnss_vel_bias_mps=0.15, dropout_per_h=0.0, gnss_gap_per_h=0.0
    )
    sc = sim.make_scenario(
        "px4_rotorcraft",
        **{**over, "realism": rl, "imu_grade": "mems"},
        gnss_mode="rtk_fixed",
        duration_s=35.0,
        parked_s=40.0,
    )
    flight = sim.simulate(sc, seed=seed)
    s = replay(write_tlog(flight, tmp_path / "in.tlog"), tmp_path / "out.tlog", Config())
    assert not [a for _, a in s.alert_log if a.code is AlertCode.FAULT]
