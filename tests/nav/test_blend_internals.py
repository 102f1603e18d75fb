"""The blend's hand-expanded small steps equal the matrix forms they replace."""

from __future__ import annotations

import numpy as np

from companion.nav import ins
from companion.nav.blend.error_model import carry_pos_vel, open_segment_cov
from companion.nav.rotations import Quat, quat_from_rotvec, quat_mul, quat_normalise


def test_carry_pos_vel_equals_the_transition_form() -> None:
    # Phi P Phi^T + Q with Phi = [[I, dt I], [0, I]] on position/velocity of an 18-state P
    rng = np.random.default_rng(4)
    for _ in range(50):
        a = rng.normal(size=(18, 18))
        p = a @ a.T
        psd = rng.uniform(1e-6, 1e-1, 3)
        dt = float(rng.uniform(0.0, 0.1))
        phi = np.eye(18)
        phi[0:3, 3:6] = dt * np.eye(3)
        q = np.zeros((18, 18))
        q[0:3, 0:3] = np.diag(psd) * dt**3 / 3.0
        q[0:3, 3:6] = q[3:6, 0:3] = np.diag(psd) * dt**2 / 2.0
        q[3:6, 3:6] = np.diag(psd) * dt
        want = phi @ p @ phi.T + q
        got = carry_pos_vel(p, dt, psd)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())


def test_mechanisation_inject_matches_the_per_component_form() -> None:
    rng = np.random.default_rng(1)
    mech = ins.Mechanisation(ins.LocalGravity(0.8, 100.0))
    mech.initialise(0.0, np.array([1.0, 2.0, -3.0]), np.array([10.0, 1.0, 0.5]), (1.0, 0, 0, 0))
    dx = rng.normal(0.0, 1e-3, 15)
    pos0, vel0 = list(mech.pos), list(mech.vel)
    q0 = mech.q_nb
    mech.inject(dx)
    assert mech.pos == [pos0[i] - float(dx[i]) for i in range(3)]
    assert mech.vel == [vel0[i] - float(dx[3 + i]) for i in range(3)]
    assert mech.ba == [-float(dx[9 + i]) for i in range(3)]
    assert mech.bg == [-float(dx[12 + i]) for i in range(3)]
    assert mech.q_nb == ins.rotate_by_psi(q0, dx[6:9])


def _random_unit_quat(rng: np.random.Generator) -> Quat:
    w, x, y, z = rng.normal(size=4)
    return quat_normalise((float(w), float(x), float(y), float(z)))


def test_carry_attitude_equals_the_composed_quaternion_form() -> None:
    rng = np.random.default_rng(12)
    mech = ins.Mechanisation(ins.LocalGravity(0.8, 100.0))
    for scale in (1e-9, 0.5):
        for _ in range(200):
            gyro = (scale * rng.normal(size=3)).tolist()
            mech.set_raw([0.0, 0.0, -9.8], gyro)
            mech.bg = (1e-4 * rng.normal(size=3)).tolist()
            q = _random_unit_quat(rng)
            dt = float(rng.uniform(-0.04, 0.04))
            g, bg = mech.last_gyro_b_radps, mech.bg
            omega_dt = [(g[i] - bg[i]) * dt for i in range(3)]
            want = quat_normalise(quat_mul(q, quat_from_rotvec(*omega_dt)))
            assert mech.carry_attitude(q, dt) == want


def test_open_segment_covariance_equals_the_array_form() -> None:

    rng = np.random.default_rng(13)
    for _ in range(100):
        a = rng.normal(size=(6, 6))
        b = a @ a.T
        psd = rng.uniform(1e-6, 1e-1, 3)
        dt = float(rng.uniform(0.0, 0.1))
        p_pos = (b[0:3, 3:6] + b[3:6, 0:3]) * dt + b[0:3, 0:3] + dt**2 * b[3:6, 3:6]
        p_pos += np.diag(psd * dt**3 / 3.0)
        p_pos = 0.5 * (p_pos + p_pos.T)
        p_vel = b[3:6, 3:6] + np.diag(psd * dt)
        got = np.array(open_segment_cov(b.tolist(), psd.tolist(), dt))
        np.testing.assert_allclose(got[:9].reshape(3, 3), p_pos, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(got[9:].reshape(3, 3), p_vel, rtol=1e-14, atol=1e-15)
