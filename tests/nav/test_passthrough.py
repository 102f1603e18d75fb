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
