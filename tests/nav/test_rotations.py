"""Rotations: the conversions agree with each other, and the float-tuple forms of the hot
paths equal the array and composed forms they stand for, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from companion.nav.rotations import (
    Quat,
    euler_to_mat_nb,
    euler_to_quat,
    euler_to_quat_values,
    mat_nb_to_euler,
    mat_to_quat,
    quat_from_rotvec,
    quat_mul,
    quat_normalise,
    quat_rotate,
    quat_to_euler,
    quat_to_mat,
    quat_to_yaw,
    rotate_by_rotvec,
    skew,
    wrap_2pi,
    wrap_pi,
)


def _random_unit_quat(rng: np.random.Generator) -> Quat:
    w, x, y, z = rng.normal(size=4)
    return quat_normalise((float(w), float(x), float(y), float(z)))


def test_euler_quaternion_matrix_agree() -> None:
    rng = np.random.default_rng(3)
    for _ in range(100):
        r, p, y = rng.uniform(-3, 3), rng.uniform(-1.5, 1.5), rng.uniform(-3, 3)
        np.testing.assert_allclose(mat_nb_to_euler(euler_to_mat_nb(r, p, y)), (r, p, y), atol=1e-9)
        np.testing.assert_allclose(quat_to_euler(euler_to_quat(r, p, y)), (r, p, y), atol=1e-9)
        q = euler_to_quat_values(r, p, y)
        assert quat_to_yaw(*q) == quat_to_euler(q)[2]


def test_quaternion_helpers_agree_with_euler_matrices() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        roll, pitch, yaw = rng.uniform(-1.4, 1.4, 3)
        q = euler_to_quat_values(roll, pitch, yaw)
        mat = euler_to_mat_nb(roll, pitch, yaw)
        np.testing.assert_allclose(quat_to_mat(q), mat, atol=1e-12)
        v = rng.normal(size=3)
        np.testing.assert_allclose(quat_rotate(q, *v), mat @ v, atol=1e-12)
        rv = rng.normal(size=3) * 0.3
        np.testing.assert_allclose(
            quat_to_mat(quat_from_rotvec(*rv)), scipy.linalg.expm(skew(rv)), atol=1e-12
        )


def test_skew_is_the_cross_product() -> None:
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(2, 3))
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), atol=1e-15)


def test_mat_to_quat_inverts_quat_to_mat_on_every_branch() -> None:
    rng = np.random.default_rng(5)
    # random rotations (mostly the trace branch) and half-turns about each axis (the
    # diagonal branches: trace -1)
    quats = [_random_unit_quat(rng) for _ in range(200)]
    quats += [quat_normalise((1e-3, a[0], a[1], a[2])) for a in np.eye(3).tolist()]
    for q in quats:
        got = mat_to_quat(quat_to_mat(q))
        assert got[0] >= 0.0
        np.testing.assert_allclose(got, q, atol=1e-12)


def test_float_euler_to_quat_is_the_array_formula_bit_for_bit() -> None:
    rng = np.random.default_rng(9)
    for roll, pitch, yaw in rng.uniform(-math.pi, math.pi, (200, 3)):
        assert euler_to_quat_values(roll, pitch, yaw) == tuple(euler_to_quat(roll, pitch, yaw))


def test_rotate_by_rotvec_equals_the_composed_quaternion_form() -> None:
    rng = np.random.default_rng(11)
    for scale in (1e-10, 1e-4, 0.3):  # both branches of the rotation-vector exponential
        for _ in range(200):
            q = _random_unit_quat(rng)
            rx, ry, rz = (scale * rng.normal(size=3)).tolist()
            want = quat_normalise(quat_mul(quat_from_rotvec(rx, ry, rz), q))
            assert rotate_by_rotvec(q, rx, ry, rz) == want


def test_wrap() -> None:
    assert wrap_pi(math.pi + 0.1) == pytest.approx(-math.pi + 0.1)
    assert wrap_pi(-math.pi - 0.1) == pytest.approx(math.pi - 0.1)
    assert wrap_2pi(-0.1) == pytest.approx(2.0 * math.pi - 0.1)
