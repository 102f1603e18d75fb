"""bench/textbook_lc.py, the textbook loosely coupled filter the walk bench measures the
service against, checked against truth: an IMU synthesised in closed form from a known
trajectory (ECEF kinematics: f = a - gamma + 2 Omega v, Groves 5.36 inverted), the
strapdown alone, a static IMU with known biases, and a noisy track whose noise matches
the filter's own model (NEES)."""

from __future__ import annotations

import importlib.util
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _tl():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("textbook_lc", ROOT / "bench" / "textbook_lc.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["textbook_lc"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


tl = _tl()
LAT0, LON0, H0 = math.radians(40.1), math.radians(-105.1), 1600.0
CEN0 = tl.c_e_n(LAT0, LON0)
R0_E = tl.llh_to_ecef(LAT0, LON0, H0)


@dataclass
class Track:
    """Level body, constant NED acceleration from a start velocity, constant yaw rate."""

    vel0_ned_mps: np.ndarray
    acc_ned_mps2: np.ndarray
    yaw0_rad: float = 0.0
    yaw_rate_rps: float = 0.0

    def truth(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ECEF position, velocity and body-to-ECEF attitude at t."""
        p_n = self.vel0_ned_mps * t + 0.5 * self.acc_ned_mps2 * t * t
        v_n = self.vel0_ned_mps + self.acc_ned_mps2 * t
        y = self.yaw0_rad + self.yaw_rate_rps * t
        rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
        return R0_E + CEN0.T @ p_n, CEN0.T @ v_n, CEN0.T @ rz

    def imu(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Specific force and angular rate (body, w.r.t. inertial space) at t."""
        r, v, c = self.truth(t)
        a_e = CEN0.T @ self.acc_ned_mps2
        omega = np.array([0.0, 0.0, tl.OMEGA_IE_RPS])
        f_e = a_e - tl.gravity_ecef(r) + 2.0 * np.cross(omega, v)
        w_b = np.array([0.0, 0.0, self.yaw_rate_rps]) + c.T @ omega
        return c.T @ f_e, w_b


def _start(track: Track, settings, c_err=None):  # type: ignore[no-untyped-def]
    """The filter started at the truth, its attitude rotated by ``c_err`` (ECEF)."""
    c_err = np.eye(3) if c_err is None else c_err
    r, v, c = track.truth(0.0)
    lat, lon, h = tl.ecef_to_llh(r)
    return tl.LcFilter.start(lat, lon, h, CEN0 @ v, CEN0 @ c_err @ c, settings)


def test_geodetic_round_trip() -> None:
    r = tl.llh_to_ecef(LAT0, LON0, H0)
    lat, lon, h = tl.ecef_to_llh(r)
    assert abs(lat - LAT0) < 1e-11 and abs(lon - LON0) < 1e-12 and abs(h - H0) < 1e-4


def test_strapdown_follows_a_turning_accelerating_track() -> None:
    """Error-free IMU at 100 Hz (interval means approximated by the mid-interval value),
    30 s accelerating at 0.3 m/s^2 while turning at 12 deg/s: the mechanisation alone
    stays within millimetres of the closed-form truth."""
    track = Track(np.array([1.0, 0.5, 0.0]), np.array([0.3, -0.2, 0.05]), 0.3, math.radians(12))
    s = tl.LcSettings(zupt=False)
    kf = _start(track, s)
    dt = 0.01
    for i in range(3000):
        f_b, w_b = track.imu((i + 0.5) * dt)
        kf.propagate(dt, f_b, w_b)
    r, v, c = track.truth(3000 * dt)
    assert np.linalg.norm(kf.r_e_m - r) < 0.005
    assert np.linalg.norm(kf.v_e_mps - v) < 5e-4
    assert np.linalg.norm(_attitude_error(kf.c_b_e, c)) < 1e-5


def _fix(kf, r_e, v_e, c_b_e, sd_p: float, sd_v: float, rng=None) -> float:  # type: ignore[no-untyped-def]
    """A GNSS fix at the antenna (truth plus seeded noise of the stated 1-sigma; the
    antenna's velocity from rotation, 5 cm x a few deg/s, is left out: < 1 mm/s)."""
    lever_e = c_b_e @ np.array(kf.settings.lever_arm_b_m)
    noise_p = rng.normal(0.0, sd_p, 3) if rng is not None else np.zeros(3)
    noise_v = rng.normal(0.0, sd_v, 3) if rng is not None else np.zeros(3)
    lat, lon, h = tl.ecef_to_llh(r_e + lever_e + CEN0.T @ noise_p)
    return kf.update_gnss(lat, lon, h, CEN0 @ v_e + noise_v, np.full(3, sd_p), np.full(3, sd_v))


def _attitude_error(c_est: np.ndarray, c_true: np.ndarray) -> np.ndarray:
    """psi with C_est = (I + [psi x]) C_true (small angles)."""
    a = c_est @ c_true.T
    return 0.5 * np.array([a[2, 1] - a[1, 2], a[0, 2] - a[2, 0], a[1, 0] - a[0, 1]])


def test_static_imu_with_known_biases() -> None:
    """At rest, level, 30 deg yaw: accelerometer bias (0.02, -0.03, 0.10) m/s^2 and gyro
    bias (0.05, -0.05, 0.10) deg/s added to the closed-form IMU, fixes at 4 Hz with
    1 cm / 5 cm seeded noise, 60 s. The vertical accelerometer bias and the three gyro
    biases (ZARU) are recovered within 3 sigma and tightly; the horizontal accelerometer
    bias is inseparable from tilt at rest, so the two together must leave the
    position still."""
    track = Track(np.zeros(3), np.zeros(3), math.radians(30.0))
    kf = _start(track, tl.LcSettings(att_unc_deg=(2.0, 2.0, 5.0)))
    rng = np.random.default_rng(7)
    b_a = np.array([0.02, -0.03, 0.10])
    b_g = np.radians([0.05, -0.05, 0.10])
    dt = 0.01
    f_b, w_b = track.imu(0.0)
    r, v, c = track.truth(0.0)
    for i in range(6000):
        kf.propagate(dt, f_b + b_a, w_b + b_g)
        if (i + 1) % 25 == 0:
            _fix(kf, r, v, c, 0.01, 0.05, rng)
    sd = np.sqrt(np.diag(kf.p))
    assert kf.zupts > 50
    err_bg = kf.bias_gyro_rps - b_g
    assert np.all(np.abs(err_bg) < 3 * sd[12:15]) and np.all(np.abs(err_bg) < math.radians(0.01))
    assert abs(kf.bias_acc_mps2[2] - b_a[2]) < max(3 * sd[11], 0.005)
    assert np.linalg.norm(kf.r_e_m - r) < 0.03 and np.linalg.norm(kf.v_e_mps) < 0.02
    # tilt absorbs the horizontal bias: -g x psi + b = 0 in the horizontal
    psi_n = CEN0 @ _attitude_error(kf.c_b_e, c)
    f_resid_n = np.cross(psi_n, np.array([0.0, 0.0, -9.8])) + CEN0 @ c @ (b_a - kf.bias_acc_mps2)
    assert np.all(np.abs(f_resid_n[0:2]) < 0.003)


def test_nees_on_a_noisy_track_with_an_outage() -> None:
    """IMU white noise and bias random walks drawn (seeded) from the filter's own model,
    start errors drawn from its initial covariance, fixes at 4 Hz at their stated 1-sigma,
    a 10 s outage from 30 s: over 4 runs the position and velocity NEES before each fix
    averages the 6 degrees of freedom, and at the outage's closure (4 samples, chi-square
    with 24 dof) is within its 99.9 % bounds."""
    s = tl.LcSettings(att_unc_deg=(1.0, 1.0, 3.0), zupt=False, yaw_align=False)
    qc = s.process_noise_psd()
    dt = 0.01
    nees_all: list[float] = []
    nees_close: list[float] = []
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        track = Track(
            np.array([1.2, 0.4, 0.0]), np.array([0.04, -0.03, 0.0]), 0.2, math.radians(8.0)
        )
        r0, v0, c0 = track.truth(0.0)
        lat, lon, h = tl.ecef_to_llh(r0)
        p0 = tl.LcFilter.start(lat, lon, h, CEN0 @ v0, CEN0 @ c0, s).p
        x0 = np.linalg.cholesky(p0) @ rng.normal(size=15)
        kf = _start(track, s, c_err=CEN0 @ (np.eye(3) + tl.skew(x0[0:3])) @ CEN0.T)
        kf.v_e_mps = kf.v_e_mps + x0[3:6]
        kf.r_e_m = kf.r_e_m + x0[6:9]
        b_a, b_g = -x0[9:12], -x0[12:15]  # true biases: the estimate (0) minus residual
        for i in range(6000):
            f_b, w_b = track.imu((i + 0.5) * dt)
            b_a = b_a + rng.normal(0.0, math.sqrt(qc[9] * dt), 3)
            b_g = b_g + rng.normal(0.0, math.sqrt(qc[12] * dt), 3)
            kf.propagate(
                dt,
                f_b + b_a + rng.normal(0.0, math.sqrt(qc[3] / dt), 3),
                w_b + b_g + rng.normal(0.0, math.sqrt(qc[0] / dt), 3),
            )
            t = (i + 1) * dt
            if (i + 1) % 25 or 30.0 <= t < 40.0:
                continue
            r, v, c = track.truth(t)
            e = np.concatenate([kf.v_e_mps - v, kf.r_e_m - r])
            nees = float(e @ np.linalg.solve(kf.p[3:9, 3:9], e))
            nees_all.append(nees)
            if abs(t - 40.0) < 1e-9:
                nees_close.append(nees)
            _fix(kf, r, v, c, 0.01, 0.05, rng)
    assert 4.5 < float(np.mean(nees_all)) < 7.5
    assert len(nees_close) == 4 and 5.0 < float(np.sum(nees_close)) < 51.2
