"""The IMU's gyro carrying the autopilot's attitude between its samples (closed forms and a
rolling, yawing vehicle whose attitude rates are sampled too coarsely)."""

from __future__ import annotations

import math
import random

import pytest

from companion.nav.blend.gyro_carry import MAX_EXTRAP_S, GyroCarry
from companion.nav.blend.rate_drift import RateDrift
from companion.nav.blend.unaided import UnaidedDeparture
from companion.nav.rotations import (
    Quat,
    euler_to_quat_values,
    quat_from_rotvec,
    quat_mul,
    rotvec_between,
)

_DEG = math.pi / 180.0
STAMP_JITTER_S = 0.004
"""The attitude message's time against its content: PX4 SIH's ATTITUDE comes every 36 to
44 ms (5th to 95th percentile) while HIGHRES_IMU's sample times are 20.0 ms apart."""


def _rates(t: float) -> list[float]:
    """Body rates of a vehicle swinging in roll and yaw at 1 Hz, out of phase (rad/s):
    0.9 rad/s (50 deg/s) peaks from 20 s on, as PX4 SIH's airplane in its loiter, a third
    of that before."""
    w = 2.0 * math.pi
    a = 0.9 if t >= 20.0 else 0.3
    return [a * math.cos(w * t), 0.0, a * math.sin(w * t)]


def _truth(duration_s: float, hz: float = 2000.0) -> list[tuple[float, Quat]]:
    """The attitude integrated finely from :func:`_rates` (the truth the autopilot
    reports), every 1/hz s."""
    q = euler_to_quat_values(0.0, 0.0, 0.0)
    out = [(0.0, q)]
    dt = 1.0 / hz
    for k in range(int(duration_s * hz)):
        t = k * dt
        w0, w1 = _rates(t), _rates(t + dt)
        q = quat_mul(
            q, quat_from_rotvec(*[(a + b) * 0.5 * dt for a, b in zip(w0, w1, strict=True)])
        )
        out.append((t + dt, q))
    return out


def test_increments_compose_to_the_rotation_between_takes() -> None:
    """A constant rate: each take returns the rotation over exactly the time since the
    last one, whatever the IMU's phase (ends carried by the nearest sample's rate)."""
    g = GyroCarry()
    w = [0.1, -0.2, 0.3]
    t_imu = [0.003 + k * 0.02 for k in range(60)]
    takes = [0.01 + k * 0.04 for k in range(25)]
    got = []
    i = 0
    for t_att in takes:
        while i < len(t_imu) and t_imu[i] <= t_att:
            g.on_imu(t_imu[i], w)
            i += 1
        got.append(g.take(t_att))
    assert got[0] is None  # nothing carried before the first take
    for dq in got[1:]:
        assert dq is not None
        r = rotvec_between(euler_to_quat_values(0.0, 0.0, 0.0), dq)
        for k in range(3):
            assert r[k] == pytest.approx(w[k] * 0.04, abs=1e-12)


def test_a_gap_in_the_imu_or_a_far_take_gives_no_increment() -> None:
    g = GyroCarry()
    g.on_imu(0.0, [0.0, 0.0, 0.1])
    assert g.take(0.0) is None
    g.on_imu(0.02, [0.0, 0.0, 0.1])
    g.on_imu(0.5, [0.0, 0.0, 0.1])  # 0.48 s without the IMU
    assert g.breaks == 1
    assert g.take(0.5) is None
    g.on_imu(0.52, [0.0, 0.0, 0.1])
    assert g.take(0.52) is not None
    assert g.take(0.52 + 2.0 * MAX_EXTRAP_S) is None


def test_a_rolling_yawing_vehicle_departs_from_coarse_rates_not_from_its_imu() -> None:
    """The autopilot's attitude is the truth, sent with its exact rates at 25 Hz, each
    message stamped up to 4 ms off its content; its IMU's gyro at 100 Hz, on time. Carried
    by the attitude's rates the heading departs by tenths of a degree in 20 s, an error the
    autopilot does not have that the gap's heading variance would count; carried by the
    IMU, by a few hundredths. Each way with its own mean departure while aided (the 20 s
    before, calmer) as the correction, as the blend does. (On PX4 SIH's airplane, 20 s of
    its loiter: 2-4.5 deg by the rates, 0.3-0.6 deg by the IMU, its heading error against
    the truth within 0.6 deg.)"""
    truth = _truth(40.0)
    rng = random.Random(7)
    step_att, step_imu = 80, 20  # 25 Hz, 100 Hz of 2 kHz
    by_rates, by_imu = UnaidedDeparture(), UnaidedDeparture()
    drift_rates, drift_imu = RateDrift(60.0), RateDrift(60.0)
    carry = GyroCarry()
    started = False
    for k, (t, q) in enumerate(truth):
        if k % step_imu == 0:
            carry.on_imu(t, _rates(t))
        if k % step_att:
            continue
        t_msg = t + rng.uniform(-STAMP_JITTER_S, STAMP_JITTER_S)
        dq = carry.take(t_msg)
        if t < 20.0:
            drift_rates.on_sample(t_msg, q, _rates(t))
            drift_imu.on_increment(t_msg, q, dq)
            continue
        if not started:
            started = True
            by_rates.start(drift_rates.mean_rate())
            by_imu.start(drift_imu.mean_rate())
        by_rates.on_sample(t_msg, q, _rates(t))
        by_imu.on_increment(t_msg, q, dq)
    rates_deg = math.sqrt(by_rates.peak_sq_rad2) / _DEG
    imu_deg = math.sqrt(by_imu.peak_sq_rad2) / _DEG
    assert rates_deg > 0.15
    assert imu_deg < 0.06
    assert by_imu.restarts == 0
