"""Solution separation: derived thresholds hold their false-alarm rate; faults are caught."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

from companion.integrity.fde.separation import ReferenceDrift, SeparationTracker, _mahalanobis3
from companion.integrity.fde.thresholds import (
    _tau_grid,
    curvature_residual_norm_s2,
    thresholds_for_times,
    thresholds_regular,
)

P_TEST = 1e-2
"""A false-alarm probability large enough to count in a few thousand windows."""


def gm_windows(rng: np.random.Generator, n_win: int, t: np.ndarray, tau: float) -> np.ndarray:
    """Independent windows of a unit-variance Gauss-Markov process (tau 0: white), (n_win, n)."""
    corr = np.eye(t.size) if tau == 0.0 else np.exp(-np.abs(t[:, None] - t[None, :]) / tau)
    chol = np.linalg.cholesky(corr + 1e-12 * np.eye(t.size))
    return rng.standard_normal((n_win, t.size)) @ chol.T


def window_stats(z: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    tc = t - t.mean()
    b = z @ tc / (tc @ tc)
    resid = z - z.mean(axis=1, keepdims=True) - b[:, None] * tc[None, :]
    return b, np.sum(resid * resid, axis=1)


def test_white_noise_thresholds_contain_s3_formulas() -> None:
    t = np.arange(40) * 0.25
    th = thresholds_for_times(t, P_TEST, P_TEST)
    tc = t - t.mean()
    white_sb = 1.0 / math.sqrt(tc @ tc)
    assert th.slope_sigma_per_s >= white_sb
    assert th.rss_threshold >= chi2.isf(P_TEST, t.size - 2) - 1e-9  # the paper's sigma^2 chi2(n-2)
    assert th.slope_threshold_per_s == pytest.approx(norm.isf(P_TEST / 2) * th.slope_sigma_per_s)


@pytest.mark.parametrize("tau_factor", [0.0, 0.05, 0.3, 1.0, 5.0])
def test_false_alarm_rate_holds_for_any_correlation_time(tau_factor: float) -> None:
    rng = np.random.default_rng(int(tau_factor * 100) + 7)
    t = np.arange(50) * 0.2  # 10 s window at 5 Hz
    th = thresholds_regular(50, 200, P_TEST, P_TEST)
    z = gm_windows(rng, 20_000, t, tau_factor * 10.0)
    b, rss = window_stats(z, t)
    fa_slope = float(np.mean(np.abs(b) > th.slope_threshold_per_s))
    fa_rss = float(np.mean(rss > th.rss_threshold))
    sd = math.sqrt(P_TEST / 20_000)
    # the worst-case correlation time makes the tests conservative, never liberal
    assert fa_slope <= P_TEST + 4 * sd
    assert fa_rss <= 1.3 * P_TEST + 4 * sd  # moment-matched chi-square: approximate tail


def test_slope_threshold_is_tight_at_the_worst_correlation_time() -> None:
    rng = np.random.default_rng(21)
    t = np.arange(50) * 0.2
    th = thresholds_regular(50, 200, P_TEST, P_TEST)
    z = gm_windows(rng, 40_000, t, th.tau_slope_s)
    b, _ = window_stats(z, t)
    assert float(np.std(b)) == pytest.approx(th.slope_sigma_per_s, rel=0.02)
    fa = float(np.mean(np.abs(b) > th.slope_threshold_per_s))
    assert fa == pytest.approx(P_TEST, abs=5 * math.sqrt(P_TEST / 40_000))


def feed(
    tracker: SeparationTracker,
    t: np.ndarray,
    noise: np.ndarray,
    fault: np.ndarray,
    sigma: np.ndarray,
) -> list[tuple[float, tuple[str, ...]]]:
    cov = np.diag(sigma**2)
    out = []
    for k in range(t.size):
        res = tracker.update(float(t[k]), noise[k] + fault[k], cov)
        out.append((float(t[k]), res.reasons))
    return out


def noise_series(
    rng: np.random.Generator, t: np.ndarray, sigma: np.ndarray, tau: float
) -> np.ndarray:
    z = gm_windows(rng, 3, t, tau).T  # (n, 3), unit variance
    return z * sigma[None, :]


SIGMA_RTK = np.array([0.015, 0.015, 0.03]) * math.sqrt(2.0)  # two receivers' difference


def test_slope_test_alone_catches_a_4cm_ramp_before_1m() -> None:
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 60.0, 0.1)
    noise = noise_series(rng, t, SIGMA_RTK, 30.0)
    ramp = np.zeros((t.size, 3))
    ramp[:, 2] = 0.04 * np.maximum(t - 20.0, 0.0)
    # snapshot test effectively off: only the window tests can fire
    tracker = SeparationTracker(10.0, 5, 1e-300, 1e-7, 1e-7)
    hits = [(tk, r) for tk, r in feed(tracker, t, noise, ramp, SIGMA_RTK) if r]
    assert hits, "ramp not detected"
    t_hit, reasons = hits[0]
    assert any(r.startswith("slope D") for r in reasons)
    assert 0.04 * (t_hit - 20.0) < 1.0
    assert t_hit > 20.0


def test_residual_test_catches_a_dither_below_the_snapshot_threshold() -> None:
    rng = np.random.default_rng(9)
    t = np.arange(0.0, 60.0, 0.1)
    noise = noise_series(rng, t, SIGMA_RTK, 30.0)
    amp = 4.0 * SIGMA_RTK[2]  # below the 6.1-sigma snapshot threshold
    dither = np.zeros((t.size, 3))
    dither[:, 2] = np.where(t >= 20.0, amp * np.sin(2 * math.pi * (t - 20.0) / 2.0), 0.0)
    tracker = SeparationTracker(10.0, 5, 1e-7, 1e-7, 1e-7)
    results = feed(tracker, t, noise, dither, SIGMA_RTK)
    residual_hits = [tk for tk, r in results if any(x.startswith("residual") for x in r)]
    snapshot_hits = [tk for tk, r in results if any(x.startswith("separation") for x in r)]
    assert residual_hits and residual_hits[0] < 30.0
    assert not [tk for tk in snapshot_hits if tk < residual_hits[0]]
    assert not [tk for tk, r in results if r and tk < 20.0]


def test_snapshot_test_catches_a_step_at_once() -> None:
    tracker = SeparationTracker(10.0, 5, 1e-7, 1e-7, 1e-7)
    cov = np.diag(SIGMA_RTK**2)
    for k in range(50):
        assert not tracker.update(0.1 * k, np.zeros(3), cov).failed
    res = tracker.update(5.0, np.array([0.0, 0.0, 0.5]), cov)
    assert res.snapshot_failed and res.failed


def test_bad_inputs_raise_and_time_reversal_restarts() -> None:
    tracker = SeparationTracker(10.0, 5, 1e-7, 1e-7, 1e-7)
    with pytest.raises(ValueError):
        tracker.update(0.0, np.array([np.nan, 0.0, 0.0]), np.eye(3))
    with pytest.raises(ValueError):
        tracker.update(0.0, np.zeros(3), -np.eye(3))
    with pytest.raises(ValueError):
        tracker.update(0.0, np.zeros(2), np.eye(3))
    for k in range(20):
        tracker.update(float(k), np.zeros(3), np.eye(3))
    res = tracker.update(3.0, np.zeros(3), np.eye(3))
    assert res.window_points == 1
    with pytest.raises(ValueError):
        SeparationTracker(0.0, 5, 1e-7, 1e-7, 1e-7)
    with pytest.raises(ValueError):
        thresholds_for_times(np.zeros(5), 1e-3, 1e-3)


def test_window_buffer_survives_long_series() -> None:
    tracker = SeparationTracker(2.0, 5, 1e-7, 1e-7, 1e-7)
    rng = np.random.default_rng(1)
    for k in range(3000):
        res = tracker.update(0.01 * k, rng.normal(size=3), np.eye(3))
    assert res.window_points == 201


def test_fast_traces_match_the_direct_generalised_chi_square() -> None:
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0.0, 8.0, 30))  # irregular on purpose
    th = thresholds_for_times(t, 1e-5, 1e-5)
    n = t.size
    x = np.column_stack((np.ones(n), t - t.mean()))
    m_res = np.eye(n) - x @ np.linalg.solve(x.T @ x, x.T)
    best = 0.0
    for tau in _tau_grid(float(t[-1] - t[0]), float(t[-1] - t[0]) / (n - 1)):
        corr = np.eye(n) if tau == 0.0 else np.exp(-np.abs(t[:, None] - t[None, :]) / tau)
        a = m_res @ corr @ m_res
        g = np.trace(a @ a) / np.trace(a)
        h = np.trace(a) ** 2 / np.trace(a @ a)
        best = max(best, g * chi2.isf(1e-5, h))
    assert th.rss_threshold == pytest.approx(best, rel=1e-9)


# ----------------------------------------------------------------------------- drifting refs


@pytest.mark.parametrize(
    ("sigma_v", "sigma_a"),
    [(0.005, 1e-4), (0.02, 1e-3), (0.002, 5e-3)],
    ids=["small", "vel", "acc"],
)
def test_drift_aware_thresholds_hold_their_false_alarm_rate(sigma_v: float, sigma_a: float) -> None:
    """Separation = receiver noise (Gauss-Markov) + an inertial reference's drift over the
    window (velocity error times t plus half the acceleration error times t^2): the slope
    and residual tests with the drift terms keep their false-alarm probability; without
    them (the plain thresholds) the drift alone trips them."""
    rng = np.random.default_rng(int(sigma_v * 1e4) + int(sigma_a * 1e5))
    n_win = 20_000
    t = np.arange(50) * 0.2
    sig_w = 0.03
    z = gm_windows(rng, n_win, t, 30.0)
    v = rng.normal(0.0, sigma_v, n_win)
    a = rng.normal(0.0, sigma_a, n_win)
    s = sig_w * z + v[:, None] * t[None, :] + 0.5 * a[:, None] * t[None, :] ** 2
    b, rss = window_stats(s / sig_w, t)
    slope_mps = b * sig_w
    tracker = SeparationTracker(10.0, 5, 1e-7, P_TEST, P_TEST)
    drift = ReferenceDrift(
        window_var_m2=np.full(3, sig_w**2),
        vel_var_m2ps2=np.full(3, sigma_v**2 + (sigma_a * t.mean()) ** 2),
        acc_var_m2ps4=np.full(3, sigma_a**2),
    )
    slope_th, rss_th = tracker.window_thresholds(t, np.full(3, sig_w), drift)
    sd = math.sqrt(P_TEST / n_win)
    fa_slope = float(np.mean(np.abs(slope_mps) > slope_th[0]))
    fa_rss = float(np.mean(rss > rss_th[0]))
    assert fa_slope <= P_TEST + 4 * sd
    assert fa_rss <= P_TEST + 4 * sd
    # the slope test stays tight (the sum of two Gaussians is exact, up to the worst-case tau)
    assert fa_slope >= 0.1 * P_TEST
    plain_slope, plain_rss = tracker.window_thresholds(t, np.full(3, sig_w))
    fa_plain = max(
        float(np.mean(np.abs(slope_mps) > plain_slope[0])), float(np.mean(rss > plain_rss[0]))
    )
    assert fa_plain > 2 * P_TEST


def test_curvature_residual_norm_closed_form() -> None:
    # t^2 about its line on n evenly spaced points: W^2 sqrt(n / 180) asymptotically
    t = np.linspace(0.0, 10.0, 2001)
    assert curvature_residual_norm_s2(t) == pytest.approx(100.0 * math.sqrt(2001 / 180.0), rel=1e-3)
    with pytest.raises(ValueError):
        curvature_residual_norm_s2(np.zeros(4))
    with pytest.raises(ValueError):
        ReferenceDrift(np.zeros(3), np.zeros(3), np.zeros(3))


def test_float_mahalanobis_matches_numpy() -> None:
    rng = np.random.default_rng(4)
    for _ in range(200):
        a = rng.normal(size=(3, 3))
        c = a @ a.T + 0.01 * np.eye(3)
        s = rng.normal(size=3)
        want = float(s @ np.linalg.solve(c, s))
        got = _mahalanobis3(*s, c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2])
        assert got == pytest.approx(want, rel=1e-9)
    with pytest.raises(ValueError):
        _mahalanobis3(1.0, 0.0, 0.0, 1.0, 2.0, 0.0, 1.0, 0.0, 1.0)  # indefinite
