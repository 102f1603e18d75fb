"""The closed-form eigenvalues behind the published accuracies, against LAPACK."""

from __future__ import annotations

import numpy as np
import pytest

from companion.types import largest_eigenvalue_2x2, largest_eigenvalue_3x3


def _spd(rng: np.random.Generator, n: int, rank: int, scale: float) -> np.ndarray:
    a = rng.standard_normal((n, rank)) * scale
    return a @ a.T


@pytest.mark.parametrize("rank", [1, 2, 3])
def test_largest_eigenvalue_3x3_equals_lapack(rank):
    rng = np.random.default_rng(40 + rank)
    for _ in range(2000):
        scale = 10.0 ** rng.uniform(-4.0, 3.0)
        m = _spd(rng, 3, rank, scale)
        want = np.linalg.eigvalsh(m)[-1]
        assert largest_eigenvalue_3x3(m.tolist()) == pytest.approx(want, rel=1e-9, abs=1e-15)


def test_largest_eigenvalue_2x2_equals_lapack():
    rng = np.random.default_rng(7)
    for _ in range(2000):
        m = _spd(rng, 2, int(rng.integers(1, 3)), 10.0 ** rng.uniform(-4.0, 3.0))
        want = np.linalg.eigvalsh(m)[-1]
        got = largest_eigenvalue_2x2(m[0, 0], m[0, 1], m[1, 1])
        assert got == pytest.approx(want, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize(
    "m",
    [
        np.eye(3) * 0.04,  # isotropic: the trigonometric form's degenerate case
        np.diag([0.01, 0.04, 0.09]),
        np.diag([0.04, 0.04, 0.01]) + 1e-9 * np.ones((3, 3)),  # a near-double eigenvalue
        np.zeros((3, 3)),
    ],
)
def test_largest_eigenvalue_3x3_degenerate_cases(m):
    assert largest_eigenvalue_3x3(m.tolist()) == pytest.approx(
        np.linalg.eigvalsh(m)[-1], rel=1e-9, abs=1e-15
    )
