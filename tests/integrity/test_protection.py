"""Protection levels: K factors from the integrity risk, d_major, Monte Carlo semantics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.integrity.protection.levels import (
    d_major_m,
    k_horizontal,
    k_vertical,
    protection_levels,
)


def test_k_factors_reproduce_do229() -> None:
    assert k_vertical(1e-7) == pytest.approx(5.33, abs=0.005)
    assert k_horizontal(5e-9) == pytest.approx(6.18, abs=0.005)


@pytest.mark.parametrize("bad", [0.0, 1.0, -1e-3, 2.0])
def test_k_factors_reject_bad_risk(bad: float) -> None:
    with pytest.raises(ValueError):
        k_vertical(bad)
    with pytest.raises(ValueError):
        k_horizontal(bad)


def test_d_major_is_the_largest_horizontal_eigen_sigma() -> None:
    rng = np.random.default_rng(11)
    for _ in range(200):
        a = rng.normal(size=(3, 3))
        cov = a @ a.T + 1e-3 * np.eye(3)
        expected = math.sqrt(np.linalg.eigvalsh(cov[:2, :2])[-1])
        assert d_major_m(cov) == pytest.approx(expected, rel=1e-12)


def test_vertical_level_is_exceeded_with_the_allocated_probability() -> None:
    # at a testable risk of 1e-2 the two-sided bound must be exact for a Gaussian
    rng = np.random.default_rng(3)
    risk, n = 1e-2, 400_000
    e = rng.normal(0.0, 2.0, n)
    pl = protection_levels(np.diag([1.0, 1.0, 4.0]), k_horizontal(risk), k_vertical(risk))
    frac = float(np.mean(np.abs(e) > pl.vpl_m))
    sd = math.sqrt(risk * (1 - risk) / n)
    assert abs(frac - risk) < 5 * sd


def test_horizontal_level_bounds_an_elliptical_error() -> None:
    rng = np.random.default_rng(4)
    risk, n = 1e-2, 400_000
    cov = np.array([[9.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    pl = protection_levels(cov, k_horizontal(risk), k_vertical(risk))
    e = rng.multivariate_normal(np.zeros(2), cov[:2, :2], n)
    frac = float(np.mean(np.hypot(e[:, 0], e[:, 1]) > pl.hpl_m))
    assert frac <= risk  # a bound for any ellipse ...
    circ = rng.normal(0.0, 3.0, (n, 2))
    pl_c = protection_levels(np.diag([9.0, 9.0, 1.0]), k_horizontal(risk), k_vertical(risk))
    frac_c = float(np.mean(np.hypot(circ[:, 0], circ[:, 1]) > pl_c.hpl_m))
    sd = math.sqrt(risk * (1 - risk) / n)
    assert abs(frac_c - risk) < 5 * sd  # ... and exact for a circle


def test_95_percent_accuracy_figures() -> None:
    rng = np.random.default_rng(5)
    n = 200_000
    pl = protection_levels(np.diag([4.0, 4.0, 9.0]), 6.18, 5.33)
    h = np.hypot(*rng.normal(0.0, 2.0, (2, n)))
    v = rng.normal(0.0, 3.0, n)
    assert float(np.mean(h <= pl.h95_m)) == pytest.approx(0.95, abs=0.003)
    assert float(np.mean(np.abs(v) <= pl.v95_m)) == pytest.approx(0.95, abs=0.003)


def test_non_finite_covariance_gives_infinite_levels() -> None:
    cov = np.eye(3)
    cov[2, 2] = np.nan
    pl = protection_levels(cov, 6.18, 5.33)
    assert math.isinf(pl.hpl_m) and math.isinf(pl.vpl_m)
    with pytest.raises(ValueError):
        protection_levels(np.eye(2), 6.18, 5.33)
