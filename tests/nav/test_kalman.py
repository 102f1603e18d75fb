"""Kalman building blocks: Van Loan against closed forms, Joseph update, gates, consistency."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from companion.nav.kalman import (
    InnovationWindow,
    chi2_gate,
    discretise_second_order,
    innovation_stats,
    joseph_update,
    joseph_update_diag_r,
    predict_covariance,
    van_loan,
)


def test_van_loan_constant_velocity_closed_form() -> None:
    q, dt = 0.7, 0.3
    f = np.array([[0.0, 1.0], [0.0, 0.0]])
    gqg = np.array([[0.0, 0.0], [0.0, q]])
    phi, qd = van_loan(f, gqg, dt)
    np.testing.assert_allclose(phi, [[1.0, dt], [0.0, 1.0]], atol=1e-14)
    expected = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    np.testing.assert_allclose(qd, expected, rtol=1e-12)


def test_van_loan_gauss_markov_closed_form() -> None:
    tau, sigma, dt = 5.0, 0.2, 0.7
    f = np.array([[-1.0 / tau]])
    gqg = np.array([[2.0 * sigma**2 / tau]])
    phi, qd = van_loan(f, gqg, dt)
    assert phi[0, 0] == pytest.approx(np.exp(-dt / tau), rel=1e-13)
    assert qd[0, 0] == pytest.approx(sigma**2 * (1 - np.exp(-2 * dt / tau)), rel=1e-12)


def test_van_loan_rejects_bad_step() -> None:
    with pytest.raises(ValueError, match="dt_s"):
        van_loan(np.zeros((1, 1)), np.zeros((1, 1)), 0.0)


def test_joseph_update_matches_textbook_form() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(5, 5))
    p = a @ a.T + np.eye(5)
    h = rng.normal(size=(2, 5))
    r = np.diag([0.3, 0.5])
    nu = rng.normal(size=2)
    c = joseph_update(p, nu, h, r)
    s = h @ p @ h.T + r
    k = p @ h.T @ np.linalg.inv(s)
    np.testing.assert_allclose(c.gain, k, rtol=1e-10)
    np.testing.assert_allclose(c.dx, k @ nu, rtol=1e-10)
    np.testing.assert_allclose(c.p_post, (np.eye(5) - k @ h) @ p, atol=1e-10)
    assert c.nis == pytest.approx(float(nu @ np.linalg.solve(s, nu)), rel=1e-12)
    assert float(c.std_innov @ c.std_innov) == pytest.approx(c.nis, rel=1e-12)
    np.testing.assert_allclose(c.p_post, c.p_post.T, atol=0.0)


def test_innovation_stats_rejects_non_pd() -> None:
    with pytest.raises(ValueError, match="positive definite"):
        innovation_stats(np.zeros((2, 2)), np.zeros(1), np.array([[1.0, 0.0]]), np.array([[-1.0]]))


def test_chi2_gate() -> None:
    assert chi2_gate(0.05, 3) == pytest.approx(7.8147, rel=1e-4)
    assert chi2_gate(1e-4, 6) == pytest.approx(float(chi2.isf(1e-4, 6)))
    with pytest.raises(ValueError):
        chi2_gate(0.0, 3)
    with pytest.raises(ValueError):
        chi2_gate(0.1, 0)


def test_filter_nees_and_nis_consistent_on_simulated_random_walk() -> None:
    """A 1-D constant-velocity filter on a seeded simulation: NEES and NIS in chi2 bounds."""
    rng = np.random.default_rng(11)
    q, r, dt, n = 0.05, 0.25, 0.2, 2000
    f = np.array([[0.0, 1.0], [0.0, 0.0]])
    phi, qd = van_loan(f, np.diag([0.0, q]), dt)
    chol_q = np.linalg.cholesky(qd)
    h = np.array([[1.0, 0.0]])
    x_true = np.array([0.0, 1.0])
    x = x_true + rng.normal(size=2)
    p = np.eye(2)
    nees, nis = [], []
    for _ in range(n):
        x_true = phi @ x_true + chol_q @ rng.normal(size=2)
        x = phi @ x
        p = predict_covariance(p, phi, qd)
        z = h @ x_true + rng.normal(scale=np.sqrt(r), size=1)
        c = joseph_update(p, z - h @ x, h, np.array([[r]]))
        x, p = x + c.dx, c.p_post
        e = x - x_true
        nees.append(float(e @ np.linalg.solve(p, e)))
        nis.append(c.nis)
    for values, dof in ((nees, 2), (nis, 1)):
        lo, hi = chi2.ppf([0.025, 0.975], dof * n) / n
        assert lo < np.mean(values) < hi


def test_innovation_window() -> None:
    w = InnovationWindow(2, 3)
    for v in (1.0, 2.0, 3.0, 4.0, float("nan")):
        w.add(0, v)
    assert w.count(0) == 3
    assert w.mean(0) == pytest.approx(3.0)
    assert np.isnan(w.mean(1))
    w.clear()
    assert w.count(0) == 0
    with pytest.raises(ValueError):
        InnovationWindow(1, 1)


def test_expm_taylor_matches_scipy() -> None:
    import scipy.linalg

    from companion.nav.kalman import expm_taylor

    rng = np.random.default_rng(5)
    for scale in (1e-3, 0.3, 2.0, 20.0):
        a = rng.normal(size=(8, 8)) * scale
        np.testing.assert_allclose(expm_taylor(a), scipy.linalg.expm(a), rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError):
        expm_taylor(np.full((2, 2), np.nan))


def test_second_order_discretisation_agrees_with_van_loan_for_short_steps() -> None:
    from companion.nav.kalman import discretise_second_order

    rng = np.random.default_rng(9)
    f = rng.normal(size=(6, 6)) * 0.5
    g = rng.uniform(0.1, 1.0, 6)
    errs = []
    for dt in (0.1, 0.05):
        phi_vl, qd_vl = van_loan(f, np.diag(g), dt)
        phi, qd = discretise_second_order(f, g, dt)
        errs.append((np.abs(phi - phi_vl).max(), np.abs(qd - qd_vl).max()))
        np.testing.assert_allclose(phi, phi_vl, atol=(0.5 * 3.0 * dt) ** 3)
        np.testing.assert_allclose(qd, qd_vl, atol=0.05 * np.abs(qd_vl).max())
    # Phi error third order, Qd error (trapezoid) third order in dt: halving dt gives ~1/8
    assert 6.0 < errs[0][0] / errs[1][0] < 10.0
    assert 6.0 < errs[0][1] / errs[1][1] < 10.0


def test_innovation_window_running_mean_matches_exact() -> None:
    rng = np.random.default_rng(2)
    w = InnovationWindow(1, 25)
    values = rng.normal(1e3, 1.0, 1000)
    for k, v in enumerate(values):
        w.add(0, float(v))
        assert w.mean(0) == pytest.approx(np.mean(values[max(0, k - 24) : k + 1]), rel=1e-12)


def test_joseph_update_diag_r_is_the_same_update_as_a_full_diagonal_r() -> None:
    # the diagonal-R variant skips the zero products of a full R: bit-identical results
    rng = np.random.default_rng(11)
    for m in (1, 3, 5, 6):
        a = rng.normal(size=(18, 18))
        p = a @ a.T + np.eye(18)
        h = np.zeros((m, 18))
        h[np.arange(m), rng.choice(18, m, replace=False)] = 1.0
        h[0, 17] = 1.0
        r = rng.uniform(0.01, 2.0, m)
        nu = rng.normal(size=m)
        full = joseph_update(p, nu, h, np.diag(r))
        diag = joseph_update_diag_r(p, nu, h, r)
        for name in ("dx", "p_post", "gain", "innov_cov", "std_innov"):
            np.testing.assert_array_equal(getattr(diag, name), getattr(full, name))
        assert diag.nis == full.nis
        # and both are the textbook update (K from S^-1, P+ = (I - K H) P)
        s = h @ p @ h.T + np.diag(r)
        k = p @ h.T @ np.linalg.inv(s)
        np.testing.assert_allclose(diag.gain, k, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(diag.p_post, (np.eye(18) - k @ h) @ p, atol=1e-9)


def test_joseph_update_rejects_an_indefinite_innovation_covariance() -> None:
    p = np.eye(3)
    with pytest.raises(ValueError, match="positive definite"):
        joseph_update(p, np.zeros(3), np.eye(3), -2.0 * np.eye(3))
    with pytest.raises(ValueError, match="positive definite"):
        joseph_update_diag_r(p, np.zeros(3), np.eye(3), np.array([1.0, -5.0, 1.0]))


def test_discretise_second_order_matches_its_formula_and_keeps_inputs() -> None:
    rng = np.random.default_rng(5)
    f = rng.normal(size=(6, 6)) * 0.3
    g = rng.uniform(0.0, 1.0, 6)
    f0, g0 = f.copy(), g.copy()
    dt = 0.1
    phi, qd = discretise_second_order(f, g, dt)
    fdt = f * dt
    want_phi = np.eye(6) + fdt + 0.5 * (fdt @ fdt)
    np.testing.assert_array_equal(phi, want_phi)
    np.testing.assert_allclose(qd, 0.5 * dt * (want_phi @ np.diag(g) @ want_phi.T + np.diag(g)))
    np.testing.assert_array_equal(f, f0)
    np.testing.assert_array_equal(g, g0)
    # the shared identity behind it is never handed out writable
    phi2, _ = discretise_second_order(f, g, dt)
    phi2 += 1.0
    np.testing.assert_array_equal(discretise_second_order(f, g, dt)[0], want_phi)
