"""What the autopilot message's quantisation costs a free-running INS.

RAW_IMU / SCALED_IMU carry whole mrad/s and mG: one gyro step is 206 deg/h,
twenty times a tactical gyro's bias. :func:`quantisation_cost` flies the same
scenario (same seed, same IMU errors) with HIGHRES_IMU (float32) and with an
integer message, dead-reckons each from the true state over a window using
only the IMU samples, and reports the position and heading errors at the end.

References
----------
Titterton & Weston, Strapdown Inertial Navigation Technology, 2nd ed., ch. 3
(quaternion attitude update); ``docs/mavlink.md`` (RAW_IMU mG, mrad/s; HIGHRES_IMU SI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.nav.rotations import euler_to_quat, quat_to_euler
from companion.nav.rotations import quat_to_mat as _mat
from companion.sim.flight import SimFlight, simulate
from companion.sim.scenarios import make_scenario
from companion.sim.trajectory import gravity_down_mps2
from companion.types import FloatArray, ImuSample


@dataclass(frozen=True, slots=True)
class DeadReckoningError:
    """Errors of a free-inertial run at the end of its window."""

    imu_message: str
    imu_grade: str
    window_s: float
    pos_err_m: float
    """Horizontal and vertical combined (3-D) position error, m."""
    yaw_err_deg: float
    tilt_err_deg: float


def _qmul(a: FloatArray, b: FloatArray) -> FloatArray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def _rotvec_quat(phi: FloatArray) -> FloatArray:
    ang = float(np.linalg.norm(phi))
    if ang < 1e-12:
        return np.array([1.0, 0.5 * phi[0], 0.5 * phi[1], 0.5 * phi[2]])
    s = math.sin(0.5 * ang) / ang
    return np.array([math.cos(0.5 * ang), s * phi[0], s * phi[1], s * phi[2]])


def dead_reckon(flight: SimFlight, t_start_s: float, window_s: float) -> DeadReckoningError:
    """Free-inertial navigation on the flight's IMU samples from the true state at ``t_start_s``.

    Attitude: rotation-vector update with the mean rate of each interval;
    velocity/position: trapezoidal with gravity at the running position.

    References
    ----------
    Titterton & Weston, ch. 3 (attitude update), ch. 3.5 (velocity/position).
    """
    imu = [
        s
        for s in flight.samples
        if isinstance(s, ImuSample) and t_start_s <= s.t_s <= t_start_s + window_s
    ]
    if len(imu) < 2:
        raise ValueError("window holds fewer than two IMU samples")
    tp = flight.truth.at(imu[0].t_s)
    q = euler_to_quat(*tp.euler_rad)
    v = tp.vel_ned_mps.copy()
    p = tp.pos_ned_m.copy()
    frame = flight.frame
    f_prev = _mat(q) @ imu[0].acc_b_mps2
    for a, b in zip(imu[:-1], imu[1:], strict=True):
        dt = b.t_s - a.t_s
        q = _qmul(q, _rotvec_quat(0.5 * (a.gyro_b_radps + b.gyro_b_radps) * dt))
        q /= np.linalg.norm(q)
        f_now = _mat(q) @ b.acc_b_mps2
        g = float(gravity_down_mps2(frame, p)[0])
        acc = 0.5 * (f_prev + f_now) + np.array([0.0, 0.0, g])
        p = p + v * dt + 0.5 * acc * dt * dt
        v = v + acc * dt
        f_prev = f_now
    te = flight.truth.at(imu[-1].t_s)
    r, pi, y = quat_to_euler(q)
    return DeadReckoningError(
        imu[0].source,
        flight.scenario.imu_grade,
        imu[-1].t_s - imu[0].t_s,
        float(np.linalg.norm(p - te.pos_ned_m)),
        math.degrees(abs(math.remainder(y - float(te.euler_rad[2]), 2 * math.pi))),
        math.degrees(math.hypot(r - float(te.euler_rad[0]), pi - float(te.euler_rad[1]))),
    )


def quantisation_cost(
    name: str = "approach",
    imu_grade: str = "tactical",
    window_s: float = 30.0,
    t_start_s: float = 40.0,
    seed: int = 1,
    imu_rate_hz: float = 100.0,
) -> tuple[DeadReckoningError, DeadReckoningError]:
    """Dead-reckoning error with HIGHRES_IMU (float32) and with RAW_IMU (mG, mrad/s integers).

    Same scenario, seed and IMU errors; only the message's quantisation differs.

    Returns
    -------
    (highres, raw) : tuple of DeadReckoningError
    """
    t_boot0_s = make_scenario(name).t_boot0_s
    out = []
    for msg in ("HIGHRES_IMU", "RAW_IMU"):
        sc = make_scenario(
            name,
            imu_message=msg,
            imu_grade=imu_grade,
            imu_rate_hz=imu_rate_hz,
            duration_s=t_start_s - t_boot0_s + window_s + 1.0,
        )
        out.append(dead_reckon(simulate(sc, seed), t_start_s, window_s))
    return out[0], out[1]
