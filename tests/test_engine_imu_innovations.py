"""The in-flight IMU grade check on simulated approaches with truth: the blend's GNSS
innovations against the configured grade (companion.nav.imu_innovations)."""

from __future__ import annotations

import logging
import math

import numpy as np

import companion.sim as sim
from companion.engine import Engine
from companion.engine.config import EngineConfig
from companion.nav.blend import BlendConfig
from companion.nav.imu_check import ImuNoiseCheck
from companion.sim.realism import Realism
from companion.types import Alert, AlertCode, ImuSample

TACTICAL = BlendConfig.for_grade("tactical", mode="strapdown")  # sitl_fixtures/tactical.toml
GYRO_MEMS_BIAS = Realism(gyro_bias_radps=0.05 * math.pi / 180.0, gyro_rw_radps_rts=3e-5)
"""A tactical unit's white noise with a MEMS gyro's turn-on bias (0.05 deg/s) and rate
random walk: a mismatch of the grade's bias figures that white noise does not show."""


def fly(flight: sim.SimFlight, engine: Engine) -> tuple[list[Alert], list[float]]:
    """The flight through the engine: its alerts, and the NIS per degree of freedom of each
    window the in-flight check judged."""
    logging.disable(logging.WARNING)
    ratios: list[float] = []
    alerts: list[Alert] = []
    judged = 0
    try:
        for s in flight.samples:
            out = engine.handle(s)
            alerts += [o for o in out if isinstance(o, Alert)]
            check = engine.imu_innovations
            if check is not None and check.judged > judged:
                judged = check.judged
                ratios.append(check.windows[-1].ratio)
    finally:
        logging.disable(logging.NOTSET)
    return alerts, ratios


def test_the_right_grade_is_not_doubted() -> None:
    flight = sim.simulate(sim.make_scenario("approach", imu_grade="tactical"), seed=1)
    engine = Engine(EngineConfig(), blend=TACTICAL)
    alerts, ratios = fly(flight, engine)
    assert not [a for a in alerts if a.code in (AlertCode.IMU_GRADE, AlertCode.FAULT)]
    check = engine.imu_innovations
    assert check is not None and check.judged >= 20
    # the blend's NIS sits below its chi-square expectation (the receiver's correlated
    # error is modelled with its full reported variance): conservative, never above
    mean = float(np.mean(ratios))
    print(
        f"right grade: mean NIS per dof of {len(ratios)} windows {mean:.2f}, max {max(ratios):.2f}"
    )
    assert 0.3 < mean < 1.0
    assert max(ratios) < check.config.min_ratio


def test_a_bias_mismatch_the_white_noise_test_misses_is_caught_by_the_innovations() -> None:
    sc = sim.make_scenario("approach", imu_grade="tactical", realism=GYRO_MEMS_BIAS)
    flight = sim.simulate(sc, seed=2)
    # the white-noise test alone: the unit's white noise is its grade's
    noise = ImuNoiseCheck(TACTICAL.gyro_arw_rad_rts, TACTICAL.accel_vrw_mps_rts)
    verdicts = [noise.on_imu(s) for s in flight.samples if isinstance(s, ImuSample)]
    judged = [v for v in verdicts if v is not None]
    assert len(judged) > 30 and not any(v.doubted for v in judged)
    engine = Engine(EngineConfig(), blend=TACTICAL)
    alerts, _ = fly(flight, engine)
    grade = [a for a in alerts if a.code is AlertCode.IMU_GRADE]
    assert len(grade) == 1 and grade[0].text.startswith("IMU innovations")
    assert "receiver not blamed" in grade[0].text
    assert grade[0].t_s < 90.0  # 80 s of flight
    # widened: the blend runs on the MEMS grade's figures, no check left running
    assert engine.imu_innovations is None and engine.imu_check is None
    mems = BlendConfig.for_grade("mems")
    assert engine.navigators.primary is not None
    assert engine.navigators.primary.config.gyro_bias_sigma_radps == mems.gyro_bias_sigma_radps  # type: ignore[attr-defined]
    # after it the receiver is fused, never reset to or excluded
    after = [a for a in alerts if a.t_s > grade[0].t_s]
    assert not [a for a in after if a.code is AlertCode.FAULT]
    assert not engine.integrity.exclude(0)


def test_mems_data_flown_as_tactical_is_caught_by_the_innovations_alone() -> None:
    flight = sim.simulate(sim.make_scenario("approach", imu_grade="mems"), seed=1)
    engine = Engine(EngineConfig(), blend=TACTICAL)
    engine.imu_check = None  # the white-noise test off: the in-flight check on its own
    alerts, _ = fly(flight, engine)
    grade = [a for a in alerts if a.code is AlertCode.IMU_GRADE]
    assert len(grade) == 1 and grade[0].text.startswith("IMU innovations")
    assert grade[0].t_s < 70.0  # 60 s of flight
    assert not [a for a in alerts if a.code is AlertCode.FAULT and a.t_s > grade[0].t_s]


def test_the_baro_and_check_blocks_reach_the_engine() -> None:
    from companion.config import config_from_dict
    from companion.pipeline import Pipeline

    cfg = config_from_dict(
        {
            "blend": {"accel_vrw_mps_rts": 0.0005, "gyro_bias_sigma_radps": 1.5e-5},
            "baro": {"noise_floor_m": 0.3, "jump_sigmas": 8.0},
            "imu_innovations": {"window_s": 20.0, "windows_needed": 2, "windows_span": 4},
        }
    )
    engine = Pipeline(cfg).engine
    assert engine.baro.config.noise_floor_m == 0.3 and engine.baro.config.jump_sigmas == 8.0
    check = engine.imu_innovations
    assert check is not None and check.config.window_s == 20.0
    assert check.windows.maxlen == 4
    # the default (MEMS) grade has nothing wider to fall back to: no check runs
    assert Pipeline(config_from_dict({})).engine.imu_innovations is None
