"""IMU grades: the error figures of each grade, used by the blend's noise model, the
coasting references and the simulator alike (one table).

Tactical: gyro drift 1-10 deg/h, accelerometer bias 0.1-1 mG (El-Mowafy 2005);
MEMS: a typical autopilot IMU after factory calibration. Densities are per sqrt(Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_DEG = math.pi / 180.0
_DEG_PER_H = _DEG / 3600.0
_MG = 9.80665e-3


@dataclass(frozen=True, slots=True)
class ImuGrade:
    """Error figures of an IMU grade (1-sigma; densities per sqrt(Hz))."""

    name: str
    gyro_bias_sigma_radps: float
    """Turn-on (constant) gyro bias, rad/s."""
    gyro_instability_radps: float
    """Gauss-Markov bias instability, rad/s."""
    gyro_tau_s: float
    gyro_noise_density_radps_rthz: float
    """Angle random walk as a noise density, rad/s/sqrt(Hz)."""
    acc_bias_sigma_mps2: float
    acc_instability_mps2: float
    acc_tau_s: float
    acc_noise_density_mps2_rthz: float


IMU_GRADES: dict[str, ImuGrade] = {
    # El-Mowafy (2005)'s tactical grade: gyro drift 1-10 deg/h; accelerometer bias 0.1-1 mG.
    "tactical": ImuGrade(
        "tactical",
        gyro_bias_sigma_radps=3.0 * _DEG_PER_H,
        gyro_instability_radps=1.0 * _DEG_PER_H,
        gyro_tau_s=300.0,
        gyro_noise_density_radps_rthz=0.05 * _DEG / 60.0,  # ARW 0.05 deg/sqrt(h)
        acc_bias_sigma_mps2=0.3 * _MG,
        acc_instability_mps2=0.05 * _MG,
        acc_tau_s=300.0,
        acc_noise_density_mps2_rthz=0.03 / 60.0,  # VRW 0.03 m/s/sqrt(h)
    ),
    # A typical autopilot MEMS IMU (ICM-4xxxx class), after factory calibration.
    "mems": ImuGrade(
        "mems",
        gyro_bias_sigma_radps=0.1 * _DEG,
        gyro_instability_radps=10.0 * _DEG_PER_H,
        gyro_tau_s=100.0,
        gyro_noise_density_radps_rthz=0.005 * _DEG,
        acc_bias_sigma_mps2=10.0 * _MG,
        acc_instability_mps2=0.2 * _MG,
        acc_tau_s=100.0,
        acc_noise_density_mps2_rthz=150e-6 * 9.80665,
    ),
    "perfect": ImuGrade("perfect", 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
}


ATTITUDE_ERROR_BY_GRADE: dict[str, tuple[tuple[float, float, float], float]] = {
    "tactical": ((0.01 * _DEG, 0.01 * _DEG, 0.02 * _DEG), 300.0),
    "mems": ((0.05 * _DEG, 0.05 * _DEG, 0.2 * _DEG), 60.0),
    "perfect": ((0.0, 0.0, 0.0), 60.0),
}
"""The autopilot's own attitude error (roll, pitch, yaw) 1-sigma [rad] and correlation
time [s], by IMU grade: an EKF on a tactical IMU (gyro bias 1-10 deg/h, i.e. at most
0.003 deg/s of drift between GNSS updates) holds its heading to a few hundredths of a
degree around its alignment error; a MEMS autopilot's heading wanders by tenths. The
constant alignment error of a fast alignment is added separately (``heading_error_deg``)."""
