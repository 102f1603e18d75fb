"""The IMU stamps' offset against the attitude stream (companion.nav.imu_stamp) and its
place in the GNSS lag measured in flight (companion.engine.gnss_lag): synthetic streams
with known offsets and lags."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.engine.gnss_lag import LagTracker, LagTrackerConfig, combine
from companion.nav.imu_stamp import ImuStampEstimator, StampOffsetConfig
from companion.nav.rotations import euler_to_mat_nb, euler_to_quat_values
from companion.types import AttitudeSample, FixType, GnssFix, ImuSample

ATT_HZ = 25.0
IMU_HZ = 50.0


def _roll_rad(t_s: np.ndarray) -> np.ndarray:
    """Rolling in and out of turns: two sines (closed form)."""
    return 0.4 * np.sin(2 * np.pi * t_s / 7.0) + 0.15 * np.sin(2 * np.pi * t_s / 2.3)


def _roll_rate_radps(t_s: np.ndarray) -> np.ndarray:
    w1, w2 = 2 * np.pi / 7.0, 2 * np.pi / 2.3
    return 0.4 * w1 * np.cos(w1 * t_s) + 0.15 * w2 * np.cos(w2 * t_s)


def _window(seed: int, offset_s: float, duration_s: float = 30.0) -> ImuStampEstimator:
    """Attitudes (roll only, noise 0.5 mrad) at their time; gyro readings (bias, noise
    0.01 rad/s) stamped ``offset_s`` after the time they measure."""
    rng = np.random.default_rng(seed)
    est = ImuStampEstimator(StampOffsetConfig(window_s=duration_s + 1.0))
    t_a = np.arange(0.0, duration_s, 1.0 / ATT_HZ)
    for t, r in zip(t_a, _roll_rad(t_a) + rng.normal(0.0, 5e-4, t_a.size), strict=True):
        est.add_attitude(float(t), euler_to_quat_values(float(r), 0.02, 1.0))
    t_g = np.arange(0.0, duration_s, 1.0 / IMU_HZ)
    p = _roll_rate_radps(t_g) + 0.003 + rng.normal(0.0, 0.01, t_g.size)
    for t, rate in zip(t_g + offset_s, p, strict=True):
        est.add_gyro(float(t), np.array([rate, -0.002, 0.001]))
    return est


@pytest.mark.parametrize("offset_s", [0.0, 0.0115, -0.02])
def test_offset_found_with_an_honest_sigma(offset_s: float) -> None:
    z = []
    for seed in range(10):
        e = _window(seed, offset_s).estimate()
        assert e is not None
        assert abs(e.offset_s - offset_s) < 0.002, e
        z.append((e.offset_s - offset_s) / e.sigma_s)
    z_rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.3 < z_rms < 1.5, z  # the sigma neither hides the error nor swamps it


def test_no_offset_without_rate_changes() -> None:
    """A steady rate (or none) says nothing about the offset."""
    est = ImuStampEstimator()
    rng = np.random.default_rng(5)
    for t in np.arange(0.0, 30.0, 1.0 / ATT_HZ):
        est.add_attitude(float(t), euler_to_quat_values(0.0, 0.0, 0.1 * float(t)))
    for t in np.arange(0.0, 30.0, 1.0 / IMU_HZ):
        est.add_gyro(float(t), np.array([0.0, 0.0, 0.1]) + rng.normal(0.0, 0.01, 3))
    e = est.estimate()
    assert e is None or e.sigma_s > 0.01


def test_measured_lag_is_against_the_attitude_clock() -> None:
    """The lag measured against late IMU stamps plus their offset: the whole lag."""
    tracker = LagTracker()
    tracker.last = combine([(0.071, 0.006), (0.070, 0.006), (0.072, 0.006)])
    tracker.imu_offset = combine([(0.0115, 0.0005)])
    m = tracker.measured()
    assert m is not None
    assert m.lag_s == pytest.approx(0.0825, abs=1e-4)
    assert m.imu_offset_s == pytest.approx(0.0115)
    assert m.sigma_s == pytest.approx(math.hypot(tracker.last.sigma_s, 0.0005))
    tracker.imu_offset = combine([(0.0115, 0.02)])  # not sure: left out
    assert tracker.measured() == tracker.last


def _turning_flight(
    tracker: LagTracker, lag_s: float, imu_late_s: float, duration_s: float, seed: int
) -> None:
    """Weaving turns (roll and heading from one closed form, level): attitudes at their
    time, IMU readings stamped ``imu_late_s`` late, fixes ``lag_s`` late."""
    rng = np.random.default_rng(seed)
    g = 9.80665
    speed = 23.0
    dt = 0.001
    t_fine = np.arange(0.0, duration_s, dt)
    roll = _roll_rad(t_fine)
    yaw_rate = g * np.tan(roll) / speed  # coordinated turn
    yaw = np.cumsum(yaw_rate) * dt
    vel = speed * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    acc = speed * np.stack([-np.sin(yaw), np.cos(yaw)], axis=1) * yaw_rate[:, None]
    p_rate = _roll_rate_radps(t_fine)
    events: list[tuple[float, object]] = []
    for t in np.arange(0.0, duration_s, 1.0 / ATT_HZ):
        i = int(round(t / dt))
        q = (float(roll[i]), 0.0, float(yaw[i]))
        events.append((t, AttitudeSample(t, t, *q, np.zeros(3))))
    for t in np.arange(0.0, duration_s, 1.0 / IMU_HZ):
        i = int(round(t / dt))
        # specific force: the horizontal acceleration less gravity, in the body
        f_ned = np.array([acc[i, 0], acc[i, 1], -g])
        f = euler_to_mat_nb(float(roll[i]), 0.0, float(yaw[i])).T @ f_ned
        sr, cr = math.sin(roll[i]), math.cos(roll[i])
        f = f + rng.normal(0.0, 0.05, 3)
        gyro = np.array([p_rate[i], yaw_rate[i] * sr, yaw_rate[i] * cr])
        ts = t + imu_late_s
        events.append((ts, ImuSample(ts, ts, f, gyro + rng.normal(0.0, 0.005, 3))))
    for t in np.arange(1.0, duration_s, 0.2):
        i = int(round(t / dt))
        v = vel[i] + rng.normal(0.0, 0.03, 2)
        ts = t + lag_s
        fix = GnssFix(ts, ts, 0, FixType.FIX_3D, 0.0, 0.0, 0.0, None, v, speed, 0.0, *[None] * 6)
        events.append((ts, fix))
    for _, s in sorted(events, key=lambda e: e[0]):
        if isinstance(s, AttitudeSample):
            tracker.on_attitude(s)
        elif isinstance(s, ImuSample):
            tracker.on_imu(s)
        else:
            tracker.on_fix(s)  # type: ignore[arg-type]


def test_tracker_measures_the_whole_lag_with_late_imu_stamps() -> None:
    """Fixes 83 ms late, IMU readings stamped 11.5 ms late (ArduPlane SITL's figures):
    against the IMU's stamps alone the lag reads ~71 ms; with the offset, 83 ms."""
    tracker = LagTracker(LagTrackerConfig())
    _turning_flight(tracker, 0.083, 0.0115, 200.0, seed=1)
    assert tracker.imu_offset is not None
    assert tracker.imu_offset.lag_s == pytest.approx(0.0115, abs=0.002)
    assert tracker.last is not None
    assert tracker.last.lag_s == pytest.approx(0.0715, abs=0.006)
    m = tracker.measured()
    assert m is not None
    assert abs(m.lag_s - 0.083) <= max(3.0 * m.sigma_s, 0.003), m
