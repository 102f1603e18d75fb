"""Pass-through navigator: exact on constant velocity, consistent innovations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from companion.nav.navigator import GnssMeasurement
from companion.nav.passthrough import PassthroughConfig, PassthroughNavigator
from companion.types import FixType


def meas(t, pos, vel, sigma_m=0.5, vel_sigma=0.1):
    return GnssMeasurement(
        t_s=t,
        pos_ned_m=np.asarray(pos, float),
        pos_var_ned_m2=np.full(3, sigma_m**2),
        vel_ned_mps=np.array([vel[0], vel[1], np.nan]),
        vel_var_ned_m2ps2=np.array([vel_sigma**2, vel_sigma**2, np.nan]),
        fix_type=FixType.FIX_3D,
    )


def test_extrapolation_is_exact_for_constant_velocity():
    nav = PassthroughNavigator()
    vel = np.array([20.0, -5.0, 1.0])
    for k in range(30):
        t = k * 0.1
        nav.on_gnss(meas(t, vel * t, vel), gate=True)
    pred = nav.predict(2.9 + 10.0)
    np.testing.assert_allclose(pred.pos_ned_m[:2], vel[:2] * 12.9, atol=1e-9)
    # no vertical velocity in GPS_RAW_INT: the height-difference EWMA (gain 0.3) has
    # converged to within 0.7**29 of the true 1 m/s after 30 fixes
    lag = 0.7**29 * vel[2] * 10.0
    assert abs(pred.pos_ned_m[2] - vel[2] * 12.9) < 2 * lag
    # covariance grows with the horizon
    p_near = nav.predict(3.0).pos_cov_ned_m2
    p_far = nav.predict(12.9).pos_cov_ned_m2
    assert np.all(np.diag(p_far) > np.diag(p_near))


def test_nis_is_chi2_consistent_on_noisy_fixes_and_gate_rate_matches():
    """Mean NIS over N fixes lies in the two-sided 99 % chi-square interval; the
    gate rejects about the configured false-alarm fraction of good fixes."""
    rng = np.random.default_rng(42)
    sigma, vel_sigma, q = 0.5, 0.1, 1e-4
    cfg = PassthroughConfig(
        accel_psd_m2ps3=q, gate_false_alarm_prob=0.01, vertical_velocity_gain=0.05
    )
    nav = PassthroughNavigator(cfg)
    vel = np.array([20.0, -5.0, 0.0])
    nis, rejected = [], 0
    n = 3000
    for k in range(n):
        t = k * 1.0
        pos = vel * t + sigma * rng.standard_normal(3)
        v = vel[:2] + vel_sigma * rng.standard_normal(2)
        upd = nav.on_gnss(meas(t, pos, v, sigma, vel_sigma), gate=True)
        if k > 50:
            nis.append(upd.nis)
            rejected += not upd.fused
    m = len(nis)
    lo, hi = chi2.ppf([0.005, 0.995], 3 * m) / m
    # the state IS the last fix, so consecutive innovations share a term: the mean is
    # consistent but the variance of the mean is larger than for independent NIS;
    # compare with 3 and a bound twice the independent half-width
    assert abs(np.mean(nis) - 3.0) < 2 * (hi - 3.0), np.mean(nis)
    assert rejected / m < 0.03


def test_diagonal_closed_form_nis_equals_the_general_solve() -> None:
    # every fix leaves the covariances diagonal: NIS is nu_i^2 / S_ii; after a frame
    # shift (rotated covariances) the general solve is used; both agree with S^-1
    from companion.nav.frames import LocalFrame

    rng = np.random.default_rng(2)
    nav = PassthroughNavigator()
    vel = np.array([15.0, 4.0, -1.0])
    for k in range(20):
        t = 0.1 * k
        pos = vel * t + rng.normal(0.0, 0.5, 3)
        pred = nav.predict(t)
        up = nav.on_gnss(meas(t, pos, vel), gate=False)
        if pred is not None:
            s = pred.pos_cov_ned_m2 + np.diag(np.full(3, 0.25))
            nu = pos - pred.pos_ned_m
            assert up.nis == pytest.approx(float(nu @ np.linalg.solve(s, nu)), rel=1e-12)
            np.testing.assert_allclose(up.innovation_cov, s, rtol=1e-15)
    old = LocalFrame(0.8, 0.1, 100.0)
    new = LocalFrame(0.8001, 0.1002, 120.0)
    nav.shift_frame(old, new)
    pred = nav.predict(2.0)
    assert pred is not None
    pos = pred.pos_ned_m + np.array([0.3, -0.2, 0.1])
    up = nav.on_gnss(meas(2.0, pos, vel), gate=False)
    s = pred.pos_cov_ned_m2 + np.diag(np.full(3, 0.25))
    nu = pos - pred.pos_ned_m
    assert up.nis == pytest.approx(float(nu @ np.linalg.solve(s, nu)), rel=1e-12)


def test_config_validation_names_the_field_and_range() -> None:
    with pytest.raises(ValueError, match=r"vertical_velocity_gain must be in \(0, 1\], got 0.0"):
        PassthroughConfig(vertical_velocity_gain=0.0)
    with pytest.raises(ValueError, match="accel_psd_m2ps3"):
        PassthroughConfig(accel_psd_m2ps3=math.nan)


def circuit(t_s: float, speed_mps: float = 25.0, radius_m: float = 200.0):
    """A plane flying straight for 60 s, then circling (3.1 m/s^2), positions and velocity."""
    if t_s < 60.0:
        return np.array([speed_mps * t_s, 0.0, 0.0]), np.array([speed_mps, 0.0])
    w = speed_mps / radius_m
    a = w * (t_s - 60.0)
    pos = np.array([speed_mps * 60.0 + radius_m * math.sin(a), radius_m * (1 - math.cos(a)), 0.0])
    return pos, np.array([speed_mps * math.cos(a), speed_mps * math.sin(a)])


def test_covariance_through_a_gap_grows_with_the_manoeuvres_seen():
    # a plane that has been circling, then loses GNSS for 20 s while still circling: the
    # constant-velocity prediction is hundreds of metres off; the covariance learnt from
    # the flight's own accelerations covers it (95 %), the configured q alone does not
    rng = np.random.default_rng(7)
    nav = PassthroughNavigator()
    for k in range(5 * 120):
        t = 0.2 * k
        pos, vel = circuit(t)
        nav.on_gnss(meas(t, pos + rng.normal(0, 0.5, 3), vel + rng.normal(0, 0.1, 2)))
    assert nav.horizontal_psd_m2ps3 > 10 * nav.config.accel_psd_m2ps3
    t_last = 0.2 * (5 * 120 - 1)
    bound95 = math.sqrt(chi2.ppf(0.95, 2))
    for gap_s in (5.0, 10.0, 20.0):
        pred = nav.predict(t_last + gap_s)
        err = np.linalg.norm(pred.pos_ned_m[:2] - circuit(t_last + gap_s)[0][:2])
        sigma_h = math.sqrt(np.trace(pred.pos_cov_ned_m2[:2, :2]) / 2)
        configured = math.sqrt(nav.config.accel_psd_m2ps3 * gap_s**3 / 3)
        assert err > 2 * bound95 * configured  # the configured q alone: confidently wrong
        assert err < bound95 * sigma_h, (gap_s, err, sigma_h)


def test_velocity_noise_alone_is_no_manoeuvre():
    rng = np.random.default_rng(3)
    nav = PassthroughNavigator()
    vel = np.array([20.0, -5.0, 0.0])
    for k in range(5 * 120):
        t = 0.2 * k
        nav.on_gnss(meas(t, vel * t + rng.normal(0, 0.5, 3), vel[:2] + rng.normal(0, 0.1, 2)))
    # noise of 0.1 m/s on each velocity: what is left after its variance is removed is
    # the flooring's small bias, within 1.5x the configured density
    assert nav.horizontal_psd_m2ps3 < 1.5 * nav.config.accel_psd_m2ps3


def test_the_vertical_velocity_variance_follows_the_receivers_error_model() -> None:
    """A 3-D receiver at 5 Hz whose height error is mostly a slow Gauss-Markov wander (the
    receiver model's white share, 10 %, on top): the height-difference vertical velocity
    is given the variance its errors really have (within 25 %), not that of independent
    fixes: 33 times too large, which put a plane's VPL over CAT I's VAL in the landing with
    the receiver's own VPL at 25 m (bench/false_alerts.py)."""
    from companion.nav.blend.receiver import GNSS_ERR_TAU_S

    rng = np.random.default_rng(7)
    sigma, dt, n = 4.0, 0.2, 20_000
    tau = GNSS_ERR_TAU_S[FixType.FIX_3D]
    phi = math.exp(-dt / tau)
    gm = np.zeros(n)
    gm[0] = rng.normal(0.0, sigma * math.sqrt(0.9))
    for k in range(1, n):
        gm[k] = phi * gm[k - 1] + sigma * math.sqrt(0.9 * (1 - phi * phi)) * rng.normal()
    err = gm + rng.normal(0.0, sigma * math.sqrt(0.1), n)
    nav = PassthroughNavigator()
    vz_err, vz_var = [], []
    for k in range(n):
        nav.on_gnss(meas(k * dt, [0.0, 0.0, err[k]], [0.0, 0.0], sigma_m=sigma), gate=False)
        if k > 100:
            state = nav.predict(k * dt)
            assert state is not None
            vz_err.append(state.vel_ned_mps[2])
            vz_var.append(state.vel_cov_ned_m2ps2[2, 2])
    ratio = float(np.mean(vz_var)) / float(np.var(vz_err))
    assert 0.8 < ratio < 1.25, ratio
