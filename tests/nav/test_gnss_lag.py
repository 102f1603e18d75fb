"""The GNSS lag from the IMU (companion.nav.gnss_lag, companion.engine.gnss_lag):
against a known lag on synthetic manoeuvres (estimate and sigma), on simulated flights,
and the tracker's combination and hand-out."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion.engine.gnss_lag import LagTracker, combine
from companion.nav.gnss_lag import GnssLagEstimator, LagConfig
from companion.sim.flight import simulate
from companion.sim.scenarios import make_scenario
from companion.types import AttitudeSample, GnssFix, ImuSample

IMU_HZ = 100.0
FIX_HZ = 5.0


def _manoeuvres(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal acceleration and its velocity (closed form): weaving turns."""
    w1, w2 = 2 * np.pi / 9.0, 2 * np.pi / 13.0
    acc = np.stack([2.0 * np.sin(w1 * t_s), 1.5 * np.cos(w2 * t_s)], axis=1)
    vel = np.stack([-2.0 / w1 * np.cos(w1 * t_s), 1.5 / w2 * np.sin(w2 * t_s)], axis=1)
    return acc, vel


def _window(seed: int, lag_s: float, duration_s: float = 60.0) -> GnssLagEstimator:
    rng = np.random.default_rng(seed)
    est = GnssLagEstimator(LagConfig(window_s=duration_s + 1.0))
    t_imu = np.arange(0.0, duration_s, 1.0 / IMU_HZ)
    acc, _ = _manoeuvres(t_imu)
    acc = acc + np.array([0.05, -0.08]) + rng.normal(0.0, 0.5, acc.shape)  # bias, vibration
    for t, a in zip(t_imu, acc, strict=True):
        est.add_acceleration(float(t), a)
    t_fix = np.arange(1.0, duration_s, 1.0 / FIX_HZ)
    _, vel = _manoeuvres(t_fix)
    vel = vel + rng.normal(0.0, 0.05, vel.shape)
    for t, v in zip(t_fix + lag_s, vel, strict=True):  # stamped lag_s after their validity
        est.add_fix(float(t), v)
    return est


@pytest.mark.parametrize("lag_s", [0.0, 0.12, 0.25])
def test_lag_found_with_an_honest_sigma(lag_s: float) -> None:
    z = []
    for seed in range(12):
        e = _window(seed, lag_s).estimate()
        assert e is not None
        z.append((e.lag_s - lag_s) / e.sigma_s)
        assert e.sigma_s < 0.02
    z_rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.3 < z_rms < 1.5, z  # the sigma neither hides the error nor swamps it


def test_no_estimate_without_manoeuvres() -> None:
    est = GnssLagEstimator()
    rng = np.random.default_rng(3)
    for t in np.arange(0.0, 60.0, 0.01):
        est.add_acceleration(float(t), rng.normal(0.0, 0.5, 2))  # vibration, no motion
    for t in np.arange(1.0, 60.0, 0.2):
        est.add_fix(float(t), np.array([10.0, 0.0]) + rng.normal(0.0, 0.05, 2))
    e = est.estimate()
    assert e is None or e.sigma_s > 0.05


def test_combination_widens_for_windows_that_disagree() -> None:
    agree = combine([(0.20, 0.02), (0.21, 0.02), (0.19, 0.02)])
    assert agree.lag_s == pytest.approx(0.20)
    assert agree.sigma_s == pytest.approx(0.02 / np.sqrt(3))
    disagree = combine([(0.20, 0.02), (-0.05, 0.02), (0.12, 0.02)])
    assert disagree.sigma_s > 5 * agree.sigma_s


def test_tracker_hands_out_a_sure_lag_once() -> None:
    tracker = LagTracker()
    tracker._windows = [(0.21, 0.02), (0.20, 0.02)]  # noqa: SLF001
    tracker.last = combine(tracker._windows)  # noqa: SLF001
    assert tracker.take() is None  # two windows are not enough
    tracker._windows.append((0.2, 0.02))  # noqa: SLF001
    tracker.last = combine(tracker._windows)  # noqa: SLF001
    m = tracker.take()
    assert m is not None and m.lag_s == pytest.approx(0.2033, abs=1e-3)
    assert tracker.take() is None  # once
    tracker.restart(m.lag_s)
    assert tracker.take() is None  # now in use


@pytest.mark.parametrize("lag_s", [0.0, 0.2])
def test_simulated_flight(lag_s: float) -> None:
    """A simulated PX4 rotorcraft's 5 minutes, its fixes stamped ``lag_s`` late: the
    combined measurement covers the lag, and a gentle flight's is not sure enough to be
    taken."""
    flight = simulate(make_scenario("px4_rotorcraft"), 0)
    tracker = LagTracker()
    for s in sorted(flight.samples, key=lambda s: s.t_rx_s):
        if isinstance(s, AttitudeSample):
            tracker.on_attitude(s)
        elif isinstance(s, ImuSample):
            tracker.on_imu(s)
        elif isinstance(s, GnssFix):
            tracker.on_fix(dataclasses.replace(s, t_s=s.t_s + lag_s))
    m = tracker.last
    assert m is not None and m.windows >= 3
    assert abs(m.lag_s - lag_s) <= 3.0 * m.sigma_s, m
    assert m.sigma_s < 0.05
    assert tracker.take() is None  # sigma over 20 ms: not taken
