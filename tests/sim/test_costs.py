"""Quantisation cost: the simulator shows what mG / mrad/s integers cost a free-running INS."""

from __future__ import annotations

from companion.sim.costs import quantisation_cost

# 30 s inside the first 180 deg coordinated turn of cruise_gnss_loss (turn starts at 60.7 s)
WINDOW = {"name": "cruise_gnss_loss", "window_s": 30.0, "t_start_s": 61.0}


def test_perfect_imu_highres_is_exact_raw_is_not() -> None:
    """Error-free IMU: float32 HIGHRES_IMU dead-reckons to mm; RAW_IMU's 1 LSB costs metres."""
    highres, raw = quantisation_cost(imu_grade="perfect", **WINDOW)
    assert highres.pos_err_m < 0.02 and highres.yaw_err_deg < 1e-3
    assert raw.pos_err_m > 1.0 and raw.yaw_err_deg > 0.1


def test_tactical_imu_loses_its_advantage_on_raw_imu() -> None:
    """A tactical gyro (3 deg/h) drifts far less than the 206 deg/h RAW_IMU step lets it."""
    highres, raw = quantisation_cost(imu_grade="tactical", **WINDOW)
    assert raw.yaw_err_deg > 2.0 * highres.yaw_err_deg
    assert raw.tilt_err_deg > 2.0 * highres.tilt_err_deg
