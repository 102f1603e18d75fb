"""The engine with a barometer through a GNSS gap, and an IMU flown with the wrong grade."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from pymavlink import mavutil

import companion.sim as sim
from companion.config import load_config
from companion.engine import Engine
from companion.engine.config import EngineConfig
from companion.replay import replay
from companion.sim.realism import Realism
from companion.types import GnssFix, NavSolution

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "sitl_fixtures"


def test_barometer_carries_the_height_through_a_gnss_gap() -> None:
    logging.disable(logging.WARNING)
    try:
        realism = Realism(baro_rate_hz=10.0, baro_noise_hpa=0.025, baro_drift_hpa_per_h=1.0)
        flight = sim.simulate(
            sim.make_scenario("approach", imu_grade="mems", realism=realism), seed=4
        )
        g0, g1 = 90.0, 110.0
        result = {}
        for use in (False, True):
            engine = Engine(EngineConfig(baro_in_blend=use))
            errs = []
            for s in flight.samples:
                if isinstance(s, GnssFix) and g0 <= s.t_s < g1:
                    continue
                for out in engine.handle(s):
                    if isinstance(out, NavSolution) and g0 + 1.0 <= out.t_s < g1:
                        alt = flight.frame.ned_to_lla(flight.truth.at(out.t_s).pos_ned_m)[2]
                        errs.append((abs(out.alt_msl_m - alt), out.v_acc_m))
            blend = engine.navigators.primary
            assert blend is not None
            result[use] = (np.array(errs), blend.diag.heights_fused)  # type: ignore[attr-defined]
    finally:
        logging.disable(logging.NOTSET)
    (_, n0), (with_baro, n1) = result[False], result[True]
    assert n0 == 0 and n1 > 150  # 10 Hz through the gap
    assert with_baro[:, 0].mean() <= 0.5
    # never confidently wrong: within 3 published sigmas throughout
    assert np.all(with_baro[:, 0] <= 3.0 * with_baro[:, 1])


def test_mems_flown_as_tactical_gets_an_imu_grade_alert_not_a_receiver_exclusion(
    tmp_path: Path,
) -> None:
    cfg = load_config(FIXTURES / "tactical.toml")
    out = tmp_path / "out.tlog"
    summary = replay(FIXTURES / "cruise_gnss_loss.tlog", out, cfg)
    assert summary.alerts.get("IMU_GRADE") == 1
    assert "FAULT" not in summary.alerts
    log = mavutil.mavlink_connection(str(out))
    first_t = None
    alert_t = None
    while True:
        msg = log.recv_match()
        if msg is None:
            break
        if first_t is None:
            first_t = log.timestamp
        if msg.get_type() == "STATUSTEXT" and "IMU_GRADE" in msg.text:
            alert_t = log.timestamp
            break
    assert first_t is not None and alert_t is not None
    assert alert_t - first_t <= 60.0
