"""INS mechanisation against closed-form trajectories, and the error model against perturbation."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from companion.nav import ins
from companion.nav.kalman import expm_taylor
from companion.nav.rotations import (
    Quat,
    euler_to_mat_nb,
    euler_to_quat,
    mat_nb_to_euler,
    quat_to_mat,
)

LAT0 = math.radians(52.0)
ALT0 = 120.0


@dataclass(frozen=True)
class Turn:
    """Closed-form flight: horizontal turn at constant speed, oscillating climb, rolling and
    pitching attitude. Every signal is an exact derivative of the position."""

    speed_mps: float = 60.0
    yaw_rate_radps: float = 0.05
    yaw0_rad: float = 0.3
    climb_amp_m: float = 15.0
    climb_omega_radps: float = 0.2
    roll0_rad: float = 0.25
    roll_amp_rad: float = 0.1
    roll_omega_radps: float = 0.3
    pitch0_rad: float = 0.05
    pitch_amp_rad: float = 0.04
    pitch_omega_radps: float = 0.5
    gravity: ins.LocalGravity = ins.LocalGravity(LAT0, ALT0)

    def euler(self, t: float) -> tuple[float, float, float]:
        roll = self.roll0_rad + self.roll_amp_rad * math.sin(self.roll_omega_radps * t)
        pitch = self.pitch0_rad + self.pitch_amp_rad * math.sin(self.pitch_omega_radps * t)
        return roll, pitch, self.yaw0_rad + self.yaw_rate_radps * t

    def euler_rates(self, t: float) -> tuple[float, float, float]:
        return (
            self.roll_amp_rad * self.roll_omega_radps * math.cos(self.roll_omega_radps * t),
            self.pitch_amp_rad * self.pitch_omega_radps * math.cos(self.pitch_omega_radps * t),
            self.yaw_rate_radps,
        )

    def pos(self, t: float) -> np.ndarray:
        v, r = self.speed_mps, self.yaw_rate_radps
        psi = self.yaw0_rad + r * t
        return np.array(
            [
                v / r * (math.sin(psi) - math.sin(self.yaw0_rad)),
                -v / r * (math.cos(psi) - math.cos(self.yaw0_rad)),
                -self.climb_amp_m * math.sin(self.climb_omega_radps * t),
            ]
        )

    def vel(self, t: float) -> np.ndarray:
        psi = self.yaw0_rad + self.yaw_rate_radps * t
        w = self.climb_omega_radps
        return np.array(
            [
                self.speed_mps * math.cos(psi),
                self.speed_mps * math.sin(psi),
                -self.climb_amp_m * w * math.cos(w * t),
            ]
        )

    def acc(self, t: float) -> np.ndarray:
        psi = self.yaw0_rad + self.yaw_rate_radps * t
        w = self.climb_omega_radps
        vr = self.speed_mps * self.yaw_rate_radps
        return np.array(
            [-vr * math.sin(psi), vr * math.cos(psi), self.climb_amp_m * w * w * math.sin(w * t)]
        )

    def mat_nb(self, t: float) -> np.ndarray:
        return euler_to_mat_nb(*self.euler(t))

    def gyro_b(self, t: float) -> np.ndarray:
        roll, pitch, _ = self.euler(t)
        dr, dp, dy = self.euler_rates(t)
        return np.array(
            [
                dr - dy * math.sin(pitch),
                dp * math.cos(roll) + dy * math.sin(roll) * math.cos(pitch),
                -dp * math.sin(roll) + dy * math.cos(roll) * math.cos(pitch),
            ]
        )

    def f_b(self, t: float) -> np.ndarray:
        p = self.pos(t)
        g = np.array([0.0, 0.0, self.gravity.down_mps2(p[0], p[2])])
        return self.mat_nb(t).T @ (self.acc(t) - g)

    def q_nb(self, t: float) -> Quat:
        q = euler_to_quat(*self.euler(t))
        return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def run_strapdown(
    traj: Turn,
    duration_s: float,
    rate_hz: float,
    *,
    acc_bias: np.ndarray | None = None,
    gyro_bias: np.ndarray | None = None,
) -> ins.Mechanisation:
    """Integrate the exact signals (plus optional biases the mechanisation knows about)."""
    mech = ins.Mechanisation(traj.gravity)
    mech.initialise(0.0, traj.pos(0.0), traj.vel(0.0), traj.q_nb(0.0))
    ba = np.zeros(3) if acc_bias is None else acc_bias
    bg = np.zeros(3) if gyro_bias is None else gyro_bias
    mech.ba = [float(c) for c in ba]
    mech.bg = [float(c) for c in bg]
    mech.set_raw(tuple(traj.f_b(0.0) + ba), tuple(traj.gyro_b(0.0) + bg))  # type: ignore[arg-type]
    n = int(round(duration_s * rate_hz))
    for k in range(1, n + 1):
        t = k / rate_hz
        mech.step(t, tuple(traj.f_b(t) + ba), tuple(traj.gyro_b(t) + bg))  # type: ignore[arg-type]
    return mech


def test_strapdown_reproduces_closed_form_turn() -> None:
    traj = Turn()
    mech = run_strapdown(traj, 60.0, 200.0)
    pos, vel = mech.state_vectors()
    assert np.linalg.norm(pos - traj.pos(60.0)) < 1e-3
    assert np.linalg.norm(vel - traj.vel(60.0)) < 1e-4
    est = mat_nb_to_euler(quat_to_mat(mech.q_nb))
    true = traj.euler(60.0)
    assert (
        max(abs(math.remainder(a - b, 2 * math.pi)) for a, b in zip(est, true, strict=True)) < 1e-5
    )


def test_strapdown_is_second_order() -> None:
    traj = Turn()
    errs = []
    for rate in (50.0, 100.0):
        mech = run_strapdown(traj, 20.0, rate)
        errs.append(np.linalg.norm(np.array(mech.pos) - traj.pos(20.0)))
    ratio = errs[0] / errs[1]
    assert 3.0 < ratio < 5.0, (errs, ratio)


def test_known_biases_are_removed() -> None:
    traj = Turn()
    ba = np.array([0.02, -0.01, 0.03])
    bg = np.array([1e-4, -2e-4, 5e-5])
    biased = run_strapdown(traj, 30.0, 100.0, acc_bias=ba, gyro_bias=bg)
    clean = run_strapdown(traj, 30.0, 100.0)
    np.testing.assert_allclose(biased.pos, clean.pos, atol=1e-9)
    np.testing.assert_allclose(biased.vel, clean.vel, atol=1e-10)


def test_error_model_matches_perturbed_integration() -> None:
    """Phi = expm(F dt) propagates small errors like the nonlinear mechanisation does."""
    traj = Turn()
    dt_total, rate = 2.0, 400.0
    rng = np.random.default_rng(7)
    dx0 = np.concatenate(
        [rng.normal(0, 0.5, 3), rng.normal(0, 0.1, 3), rng.normal(0, 1e-3, 3)]
        + [rng.normal(0, 0.02, 3), rng.normal(0, 2e-4, 3)]
    )
    ref = run_strapdown(traj, dt_total, rate)
    # perturbed: start from the truth with the error dx0 injected (estimate = truth + error)
    mech = ins.Mechanisation(traj.gravity)
    mech.initialise(
        0.0,
        traj.pos(0.0) + dx0[0:3],
        traj.vel(0.0) + dx0[3:6],
        ins.rotate_by_psi(traj.q_nb(0.0), -dx0[6:9]),
    )
    # bias estimate = truth (zero) + error: the mechanisation subtracts it from exact signals
    mech.ba = [float(c) for c in dx0[9:12]]
    mech.bg = [float(c) for c in dx0[12:15]]
    mech.set_raw(tuple(traj.f_b(0.0)), tuple(traj.gyro_b(0.0)))  # type: ignore[arg-type]
    phi = np.eye(ins.N_ERR)
    n = int(dt_total * rate)
    for k in range(1, n + 1):
        t = k / rate
        mech.step(t, tuple(traj.f_b(t)), tuple(traj.gyro_b(t)))  # type: ignore[arg-type]
        dt_seg, f_ned = mech.take_segment()
        f_mat = ins.error_model_f(
            f_ned,
            traj.mat_nb(t - 0.5 / rate),
            strapdown=True,
            tau_att_s=math.inf,
            tau_ba_s=math.inf,
            tau_bg_s=math.inf,
        )
        phi = expm_taylor(f_mat * dt_seg) @ phi
    predicted = phi @ dx0
    actual_pos = np.array(mech.pos) - np.array(ref.pos)
    actual_vel = np.array(mech.vel) - np.array(ref.vel)
    # attitude error: C_hat = (I - [psi x]) C  ->  [psi x] = I - C_hat C^T
    c_err = np.eye(3) - quat_to_mat(mech.q_nb) @ quat_to_mat(ref.q_nb).T
    actual_psi = np.array([c_err[2, 1], c_err[0, 2], c_err[1, 0]])
    # second-order terms of a 0.5 m / 1 mrad perturbation: agreement to a few per cent
    np.testing.assert_allclose(actual_pos, predicted[0:3], atol=0.02 * np.abs(predicted[0:3]).max())
    np.testing.assert_allclose(actual_vel, predicted[3:6], atol=0.02 * np.abs(predicted[3:6]).max())
    np.testing.assert_allclose(actual_psi, predicted[6:9], atol=0.02 * np.abs(predicted[6:9]).max())


def test_inject_removes_error() -> None:
    traj = Turn()
    mech = ins.Mechanisation(traj.gravity)
    q_true = traj.q_nb(0.0)
    dx = np.zeros(ins.N_ERR)
    dx[0:3] = [1.0, -2.0, 0.5]
    dx[3:6] = [0.1, 0.2, -0.3]
    dx[6:9] = [1e-3, -2e-3, 5e-3]
    dx[9:12] = [0.01, 0.02, 0.03]
    dx[12:15] = [1e-4, 2e-4, 3e-4]
    mech.initialise(
        0.0, traj.pos(0.0) + dx[0:3], traj.vel(0.0) + dx[3:6], ins.rotate_by_psi(q_true, -dx[6:9])
    )
    mech.ba = list(dx[9:12])
    mech.bg = list(dx[12:15])
    mech.inject(dx)
    np.testing.assert_allclose(mech.pos, traj.pos(0.0), atol=1e-12)
    np.testing.assert_allclose(mech.vel, traj.vel(0.0), atol=1e-12)
    np.testing.assert_allclose(mech.ba, 0.0, atol=1e-15)
    np.testing.assert_allclose(quat_to_mat(mech.q_nb), traj.mat_nb(0.0), atol=1e-10)


def test_gravity_follows_height_and_latitude() -> None:
    g = ins.LocalGravity(LAT0, ALT0)
    assert g.down_mps2(0.0, -1000.0) < g.down_mps2(0.0, 0.0)
    # free-air gradient about 3.086e-6 s^-2
    grad = (g.down_mps2(0.0, 0.0) - g.down_mps2(0.0, -100.0)) / 100.0
    assert grad == pytest.approx(3.086e-6, rel=0.01)
    assert g.down_mps2(100e3, 0.0) > g.down_mps2(0.0, 0.0)  # northward at 52 deg N: stronger
