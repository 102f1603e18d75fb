"""The IMU's measured white noise against its configured grade."""

from __future__ import annotations

import math

import numpy as np

from companion.nav.grades import IMU_GRADES
from companion.nav.imu_check import ImuNoiseCheck
from companion.types import ImuSample


def verdicts(check: ImuNoiseCheck, gyro_q: float, acc_q: float, seconds: float, seed: int):
    """HIGHRES readings at 100 Hz in a slow turn with white noise of these densities."""
    rng = np.random.default_rng(seed)
    rate = 100.0
    out = []
    for k in range(int(seconds * rate)):
        t = k / rate
        gyro = np.array([0.0, 0.0, 0.1 * math.sin(0.2 * t)]) + rng.normal(0, gyro_q * 10.0, 3)
        acc = np.array([0.5 * math.sin(0.3 * t), 0.0, -9.8]) + rng.normal(0, acc_q * 10.0, 3)
        v = check.on_imu(ImuSample(t, t, acc, gyro, 0, "HIGHRES_IMU"))
        if v is not None:
            out.append(v)
    return out


def test_the_right_grade_is_not_doubted_a_noisier_imu_is() -> None:
    tac, mems = IMU_GRADES["tactical"], IMU_GRADES["mems"]
    right = ImuNoiseCheck(mems.gyro_noise_density_radps_rthz, mems.acc_noise_density_mps2_rthz)
    out = verdicts(
        right, mems.gyro_noise_density_radps_rthz, mems.acc_noise_density_mps2_rthz, 60.0, 1
    )
    assert len(out) == 11  # (6000 readings give 5998 second differences)
    assert not any(v.doubted for v in out)
    assert all(0.8 < v.gyro_ratio < 1.25 and 0.8 < v.acc_ratio < 1.25 for v in out)
    wrong = ImuNoiseCheck(tac.gyro_noise_density_radps_rthz, tac.acc_noise_density_mps2_rthz)
    out = verdicts(
        wrong, mems.gyro_noise_density_radps_rthz, mems.acc_noise_density_mps2_rthz, 10.0, 2
    )
    assert out and all(v.doubted for v in out)
