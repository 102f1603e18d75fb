"""The strapdown blend's gyro process noise follows the gyro's measured white noise when
that is larger than configured beyond chance, and keeps the configured density otherwise
(bit for bit: a correct grade changes nothing)."""

from __future__ import annotations

import math

import numpy as np

from companion.nav import ins
from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.frames import LocalFrame
from companion.types import AttitudeSample, ImuSample

FRAME = LocalFrame(math.radians(40.0), 0.0, 1600.0)
G_MPS2 = ins.LocalGravity(FRAME.lat0_rad, FRAME.alt0_m).down_mps2(0.0, 0.0)
IMU_HZ = 200.0
ARW = 0.005 * math.pi / 180.0  # rad/s/sqrt(Hz), the MEMS grade's


def feed(
    blend: BlendNavigator, gyro_density: float, n: int, rng: np.random.Generator, t0: float = 0.0
) -> float:
    """``n`` samples at rest with gyro white noise of ``gyro_density`` (rad/s/sqrt(Hz));
    returns the time of the last."""
    sigma = gyro_density * math.sqrt(IMU_HZ)  # per sample, the convention of imu_check
    t = t0
    for k in range(n):
        t = t0 + k / IMU_HZ
        gyro = rng.normal(0.0, sigma, 3) if sigma > 0.0 else np.zeros(3)
        blend.on_imu(ImuSample(t, t, np.array([0.0, 0.0, -G_MPS2]), gyro, source="HIGHRES_IMU"))
    return t


def test_a_gyro_noisier_than_configured_drives_the_attitude_error() -> None:
    """Ten times the configured density: after one window (500 samples) the PSD in use is
    the measured one, 100 times the configured, within the window's spread (about 5 %)."""
    cfg = BlendConfig(mode="strapdown", gyro_arw_rad_rts=ARW)
    blend = BlendNavigator(cfg, FRAME)
    q0 = ARW**2
    assert blend.diag.gyro_psd == q0
    feed(blend, 10.0 * ARW, 600, np.random.default_rng(1))
    assert 80.0 < blend.diag.gyro_psd / q0 < 120.0
    assert np.all(blend._model.gqg[6:9] == blend.diag.gyro_psd)


def test_a_gyro_as_configured_keeps_the_configured_density_exactly() -> None:
    """At the configured density the measured ratio stays below the threshold: the model is
    the one without the measurement, value for value."""
    rng_a, rng_b = np.random.default_rng(2), np.random.default_rng(2)
    on = BlendNavigator(BlendConfig(mode="strapdown", gyro_arw_rad_rts=ARW), FRAME)
    off = BlendNavigator(
        BlendConfig(mode="strapdown", gyro_arw_rad_rts=ARW, gyro_noise_measured=False), FRAME
    )
    feed(on, ARW, 2000, rng_a)
    feed(off, ARW, 2000, rng_b)
    assert on.diag.gyro_psd == ARW**2
    assert np.array_equal(on._model.gqg, off._model.gqg)


def test_the_density_returns_to_the_configured_one_when_the_noise_does() -> None:
    """Noisy windows, then quiet ones: the measured PSD is used while it lasts."""
    blend = BlendNavigator(BlendConfig(mode="strapdown", gyro_arw_rad_rts=ARW), FRAME)
    rng = np.random.default_rng(3)
    t = feed(blend, 10.0 * ARW, 600, rng)
    assert blend.diag.gyro_psd > 10.0 * ARW**2
    feed(blend, ARW, 1200, rng, t0=t + 1.0 / IMU_HZ)
    assert blend.diag.gyro_psd == ARW**2


def test_attitude_aided_mode_keeps_its_attitude_noise() -> None:
    """With the autopilot's attitude the attitude error is the autopilot's: a noisy gyro
    does not change the model (the measurement does not even run)."""
    cfg = BlendConfig(gyro_arw_rad_rts=ARW)
    blend = BlendNavigator(cfg, FRAME)
    gqg0 = blend._model.gqg.copy()
    blend.on_attitude(AttitudeSample(0.0, 0.0, 0.0, 0.0, 0.0, np.zeros(3)), 0.0)
    feed(blend, 10.0 * ARW, 600, np.random.default_rng(4))
    assert np.array_equal(blend._model.gqg, gqg0)
    assert math.isnan(blend.diag.gyro_psd)
