"""The accelerometer's white noise measured in use (companion.nav.blend.accel_noise): a
vibrating IMU's measured density drives the blend's velocity error, so its covariance says
how good the prediction is and consistent fixes pass the gate."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from companion.nav.blend import BlendNavigator
from companion.nav.blend.accel_noise import AccelNoise
from companion.nav.grades import IMU_GRADES
from companion.nav.navigator import GnssMeasurement
from companion.types import ImuSample
from tests.nav.test_blend import FRAME, SimSpec, Trace, config_for, nees, run, simulate

MEMS = IMU_GRADES["mems"]
GYRO_Q = MEMS.gyro_noise_density_radps_rthz
ACC_Q = MEMS.acc_noise_density_mps2_rthz


def _imu(rng: np.random.Generator, t_s: float, sigma_mps2: float) -> ImuSample:
    acc = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, sigma_mps2, 3)
    gyro = rng.normal(0.0, GYRO_Q * math.sqrt(50.0), 3)
    return ImuSample(t_s, t_s, acc, gyro, source="HIGHRES_IMU")


def test_measured_psd_is_the_variance_per_sample_over_the_rate() -> None:
    rng = np.random.default_rng(1)
    noise = AccelNoise(GYRO_Q, ACC_Q)
    sigma = 0.7  # m/s^2 per sample at 50 Hz: a copter's aliased vibration, ~100x MEMS
    for k in range(1000):
        noise.on_imu(_imu(rng, k / 50.0, sigma))
    assert noise.measured
    assert abs(noise.psd_m2ps3 / (sigma**2 / 50.0) - 1.0) < 0.3, noise.psd_m2ps3


def test_an_imu_within_its_grade_keeps_the_configured_density() -> None:
    rng = np.random.default_rng(2)
    noise = AccelNoise(GYRO_Q, ACC_Q)
    for k in range(1000):
        noise.on_imu(_imu(rng, k / 50.0, ACC_Q * math.sqrt(50.0)))
    assert not noise.measured
    assert noise.psd_m2ps3 == ACC_Q**2


def test_vibration_is_followed_at_once_and_let_go_after_the_hold() -> None:
    rng = np.random.default_rng(3)
    noise = AccelNoise(GYRO_Q, ACC_Q)
    quiet = ACC_Q * math.sqrt(50.0)
    t = 0.0
    for _ in range(500):  # 10 s quiet, 10 s vibrating, then quiet again
        noise.on_imu(_imu(rng, t, quiet))
        t += 0.02
    assert not noise.measured
    for _ in range(150):  # within one 2 s window (and the next) of the start
        noise.on_imu(_imu(rng, t, 0.7))
        t += 0.02
    assert noise.measured
    for _ in range(350):
        noise.on_imu(_imu(rng, t, 0.7))
        t += 0.02
    for _ in range(250):  # 5 s quiet: still held
        noise.on_imu(_imu(rng, t, quiet))
        t += 0.02
    assert noise.measured
    for _ in range(400):  # 13 s quiet: let go
        noise.on_imu(_imu(rng, t, quiet))
        t += 0.02
    assert not noise.measured


def _run_stream(rate_hz: float, acc_at: object, seconds: float = 30.0) -> AccelNoise:
    noise = AccelNoise(GYRO_Q, ACC_Q)
    rng = np.random.default_rng(4)
    for k in range(int(seconds * rate_hz)):
        t = k / rate_hz
        acc = np.array([0.0, 0.0, -9.81]) + acc_at(t, rng)  # type: ignore[operator]
        gyro = rng.normal(0.0, GYRO_Q * math.sqrt(rate_hz), 3)
        noise.on_imu(ImuSample(t, t, acc, gyro, source="HIGHRES_IMU"))
    return noise


def test_a_tone_aliased_near_nyquist_is_not_counted_as_integrating_noise() -> None:
    # a rotor harmonic at 120 Hz sampled at 250 Hz (near Nyquist: its second differences
    # are 16/6 of its variance) over a white floor; it integrates into millimetres per
    # second, the floor into the velocity error: the PSD in use is the floor's (within
    # the upper confidence bound the increments are taken at), not the tone's
    rate, white = 250.0, 0.1
    phase = np.array([0.3, 1.7, 2.9])

    def acc(t: float, rng: np.random.Generator) -> np.ndarray:
        return 0.3 * np.sin(2.0 * math.pi * 120.0 * t + phase) + rng.normal(0.0, white, 3)

    noise = _run_stream(rate, acc)
    floor = white**2 / rate
    samples = (
        white**2 + 0.3**2 / 2.0 * (2.0 - 2.0 * math.cos(2.0 * math.pi * 120.0 / rate)) ** 2 / 6.0
    ) / rate
    assert noise.measured
    assert samples > 10.0 * floor  # what the samples' second differences alone gave
    assert noise.psd_m2ps3 < 2.5 * floor, (noise.psd_m2ps3, floor)
    assert noise.psd_m2ps3 > 0.8 * floor, (noise.psd_m2ps3, floor)


def test_slow_motion_is_not_counted_as_noise() -> None:
    # a walker's gait (2 Hz, 3 m/s^2) moves the 0.1 s increments far more than any noise:
    # the increments never raise the PSD above the samples' own
    rate, white = 100.0, 0.3

    def acc(t: float, rng: np.random.Generator) -> np.ndarray:
        return 3.0 * np.sin(2.0 * math.pi * 2.0 * t + np.array([0.0, 1.0, 2.0])) + rng.normal(
            0.0, white, 3
        )

    noise = _run_stream(rate, acc)
    assert noise.low_band_ratio == 1.0
    assert abs(noise.psd_m2ps3 / (white**2 / rate) - 1.0) < 0.3, noise.psd_m2ps3


def _vibrating_run(seed: int, **overrides: object) -> tuple[BlendNavigator, Trace, int]:
    """An RTK flight on an IMU 70 times noisier (1-sigma) than the MEMS density the blend
    is configured with: the blend, its trace, and the fixes gated after the first 10 s."""
    spec = SimSpec(
        duration_s=40.0,
        acc_vrw=0.1,  # 0.7 m/s^2 per sample at 50 Hz
        pos_sigma_true=(0.015, 0.015, 0.03),
        pos_sigma_reported=(0.015, 0.015, 0.03),
        vel_sigma_true=0.02,
        vel_sigma_reported=0.02,
    )
    sim = simulate(spec, seed)
    nav = BlendNavigator(config_for(spec, accel_vrw_mps_rts=ACC_Q, **overrides), FRAME)
    late = [s for s in sim.samples if not (isinstance(s, GnssMeasurement) and s.t_s < 10.0)]
    gated_late = run(nav, type(sim)(late, spec), t_check_from=1e9).gated
    nav = BlendNavigator(config_for(spec, accel_vrw_mps_rts=ACC_Q, **overrides), FRAME)
    trace = run(nav, sim, check_every_s=0.5, t_check_from=15.0)
    return nav, trace, gated_late


def test_a_vibrating_imu_keeps_the_fixes_and_an_honest_covariance() -> None:
    for seed in (1, 2):
        nav, trace, gated = _vibrating_run(seed)
        # the gate's false-alarm probability is 1e-4 per fix: none expected in 150
        assert gated <= 1, (seed, gated)
        ratio = nav.q_estimate_accel_psd / 0.1**2
        assert np.all((ratio > 0.8) & (ratio < 2.0)), ratio
        assert float(np.mean(nees(trace, slice(3, 6)))) < 4.5  # 3 dof


def test_with_the_datasheet_density_the_fixes_are_gated() -> None:
    # what the blend did before it measured the noise: its prediction claimed millimetres
    # per second, every fix that disagreed was gated, the velocity NEES in the tens
    _, trace, gated = _vibrating_run(1, accel_noise_measured=False)
    assert gated > 100
    assert float(np.mean(nees(trace, slice(3, 6)))) > 10.0


def _tone_run(seed: int) -> tuple[BlendNavigator, Trace]:
    """An RTK flight on a 250 Hz IMU whose white floor (0.01 m/s/sqrt(s)) carries a
    rotor harmonic at 120 Hz of 0.5 m/s^2 (near Nyquist: 13 times the floor's second
    differences), the blend configured with the MEMS density."""
    spec = SimSpec(
        duration_s=40.0,
        imu_hz=250.0,
        acc_vrw=0.01,
        pos_sigma_true=(0.015, 0.015, 0.03),
        pos_sigma_reported=(0.015, 0.015, 0.03),
        vel_sigma_true=0.02,
        vel_sigma_reported=0.02,
    )
    sim = simulate(spec, seed)
    phase = np.array([0.3, 1.7, 2.9])
    samples = [
        dataclasses.replace(
            s, acc_b_mps2=s.acc_b_mps2 + 0.5 * np.sin(2.0 * math.pi * 120.0 * s.t_s + phase)
        )
        if isinstance(s, ImuSample)
        else s
        for s in sim.samples
    ]
    nav = BlendNavigator(config_for(spec, accel_vrw_mps_rts=ACC_Q), FRAME)
    trace = run(nav, type(sim)(samples, spec), check_every_s=0.5, t_check_from=15.0)
    return nav, trace


def test_a_rotor_tone_does_not_make_the_velocity_covariance_pessimistic() -> None:
    # the tone integrates into 0.7 mm/s: the velocity error is the floor's. Counted as
    # noise at its second differences (15 times the floor) the velocity covariance
    # claimed more than the error (NEES 0.66 and 0.81 for 3 dof) and the vertical
    # followed the fixes more than the IMU warranted
    for seed in (1, 2):
        nav, trace = _tone_run(seed)
        # the floor of the adaptive Q is the measured PSD (an axis may be raised above it)
        floor = float(np.min(nav.q_estimate_accel_psd)) / 0.01**2
        assert 0.8 < floor < 2.5, (seed, floor)
        assert float(np.mean(nees(trace, slice(3, 6)))) > 1.0, seed  # 3 dof
