"""Simulated errors match their configured statistics (seeded; chi-square bounds)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from companion.nav.grades import IMU_GRADES
from companion.sim import make_scenario, simulate
from companion.sim.sensors import (
    GNSS_MODE_SPECS,
    gauss_markov,
    gauss_markov_fast,
    gnss_state,
    imu_errors,
)

P_FALSE = 1e-3  # probability that a correct model fails one check


def _var_in_chi2_bounds(x: np.ndarray, sigma: float, dof: int) -> bool:
    """Sample variance of zero-mean data with ``dof`` effective samples inside chi2 bounds."""
    s = float(np.sum(x**2) / x.size) * dof / sigma**2
    lo = stats.chi2.ppf(P_FALSE / 2, dof)
    hi = stats.chi2.ppf(1 - P_FALSE / 2, dof)
    return bool(lo <= s <= hi)


def test_white_noise_variance_matches_density() -> None:
    grade = IMU_GRADES["mems"]
    rate = 200.0
    err = imu_errors(np.random.default_rng(11), grade, 20000, rate)
    sg = grade.gyro_noise_density_radps_rthz * math.sqrt(rate)
    sa = grade.acc_noise_density_mps2_rthz * math.sqrt(rate)
    for k in range(3):
        assert _var_in_chi2_bounds(err.gyro_white_b_radps[:, k], sg, 20000)
        assert _var_in_chi2_bounds(err.acc_white_b_mps2[:, k], sa, 20000)
    # and a wrong sigma is caught
    assert not _var_in_chi2_bounds(err.gyro_white_b_radps[:, 0], 1.1 * sg, 20000)


def test_turn_on_bias_statistics() -> None:
    """Turn-on biases over many seeds: variance in chi2 bounds for the grade's sigma."""
    grade = IMU_GRADES["tactical"]
    b = np.array(
        [
            imu_errors(np.random.default_rng(s), grade, 2, 100.0).gyro_bias_b_radps[0]
            for s in range(400)
        ]
    )
    # the Gauss-Markov instability adds its variance to the turn-on bias at any instant
    sig = math.hypot(grade.gyro_bias_sigma_radps, grade.gyro_instability_radps)
    assert _var_in_chi2_bounds(b.ravel(), sig, b.size)
    assert abs(b.mean()) < 4 * sig / math.sqrt(b.size)


def test_gauss_markov_variance_and_correlation() -> None:
    """Stationary variance sigma^2 and lag correlation exp(-dt/tau), both forms."""
    dt, tau, sigma, n = 0.1, 2.0, 0.7, 200_000
    for x in (
        gauss_markov_fast(np.random.default_rng(5), n, dt, sigma, tau, 1)[:, 0],
        gauss_markov(np.random.default_rng(6), np.arange(n) * dt, sigma, tau, 1)[:, 0],
    ):
        phi = math.exp(-dt / tau)
        # effective independent samples of a AR(1) variance estimate: n (1 - phi^2) / (1 + phi^2)
        n_eff = int(n * (1 - phi**2) / (1 + phi**2))
        assert _var_in_chi2_bounds(x, sigma, n_eff)
        r1 = float(np.sum(x[1:] * x[:-1]) / np.sum(x**2))
        # innovations x_k - phi x_{k-1} are white with variance sigma^2 (1 - phi^2)
        innov = x[1:] - phi * x[:-1]
        assert _var_in_chi2_bounds(innov, sigma * math.sqrt(1 - phi**2), n - 1)
        assert abs(r1 - phi) < 5 * math.sqrt((1 - phi**2) / n)


def test_flight_imu_errors_are_the_configured_ones() -> None:
    """Samples minus truth minus injected bias = white noise of the grade (+ float32 rounding)."""
    sc = make_scenario("approach", duration_s=60.0)
    f = simulate(sc, 4)
    imu = [s for s in f.samples if type(s).__name__ == "ImuSample"]
    gyro = np.array([s.gyro_b_radps for s in imu])
    assert len(imu) == len(f.truth.t_s)
    resid = gyro - f.truth.gyro_b_radps - f.errors.imu.gyro_bias_b_radps
    sg = IMU_GRADES["tactical"].gyro_noise_density_radps_rthz * math.sqrt(sc.imu_rate_hz)
    for k in range(3):
        assert _var_in_chi2_bounds(resid[:, k], sg, len(resid))


def test_raw_imu_quantisation_is_one_lsb() -> None:
    """RAW_IMU with a perfect IMU: samples are whole mrad/s and mG, within half an LSB of truth."""
    sc = make_scenario("cruise_gnss_loss", duration_s=60.0, imu_grade="perfect")
    f = simulate(sc, 2)
    imu = [s for s in f.samples if type(s).__name__ == "ImuSample"]
    q = np.array([s.gyro_b_radps for s in imu]) - f.truth.gyro_b_radps
    assert np.abs(q).max() <= 0.5e-3 + 1e-12
    g_mrad = np.array([s.gyro_b_radps for s in imu]) * 1e3
    np.testing.assert_allclose(g_mrad, np.rint(g_mrad), atol=1e-9)
    a_mg = np.array([s.acc_b_mps2 for s in imu]) * 1000.0 / 9.80665
    np.testing.assert_allclose(a_mg, np.rint(a_mg), atol=1e-9)
    qa = np.array([s.acc_b_mps2 for s in imu]) - f.truth.f_b_mps2
    assert np.abs(qa).max() <= 0.5 * 9.80665e-3 + 1e-12


def test_gnss_position_error_statistics_per_mode() -> None:
    """Receiver position error: per-axis sigma of the mode, correlation time of the mode."""
    for mode in ("rtk_fixed", "3d"):
        sc = make_scenario(
            "cruise_gnss_loss", gnss_mode=mode, events=(), cruise_s=900.0, imu_rate_hz=5.0
        )
        f = simulate(sc, 9)
        g = f.errors.gnss[0]
        spec = GNSS_MODE_SPECS[mode]
        phi = math.exp(-(1.0 / sc.gnss_rate_hz) / spec.tau_s)
        n = len(g.t_fix_s)
        for k, sig in enumerate((spec.sigma_h_m, spec.sigma_h_m, spec.sigma_v_m)):
            x = g.pos_err_ned_m[:, k]
            innov = x[1:] - phi * x[:-1]
            assert _var_in_chi2_bounds(innov, sig * math.sqrt(1 - phi**2), n - 1)
        v = g.vel_err_ned_mps
        assert _var_in_chi2_bounds(
            v[:, :2], sc.gnss_vel_noise_mps * spec.vel_noise_scale, v[:, :2].size
        )


def test_rtk_outage_schedule() -> None:
    """Corrections lost: fixed (extrapolated) -> float -> 3D, then float -> fixed after."""
    sc = make_scenario("approach_rtk20")
    ev = sc.events[0]
    t0, t1 = ev.t_start_s, ev.t_end_s
    labels = [gnss_state(sc, 0, t).label for t in (t0 - 1, t0 + 1, t0 + 5, t0 + 15, t1 + 1, t1 + 9)]
    assert labels == ["rtk_fixed", "rtk_fixed", "rtk_float", "3d", "rtk_float", "rtk_fixed"]
