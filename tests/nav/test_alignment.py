"""The blend's own alignment (no autopilot attitude): levelling at rest against the closed
form, yaw from GNSS velocity changes, and the blend started from it on a seeded flight that
rests, then walks off in a turn (consistency by NEES)."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from companion.nav import ins
from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.blend.alignment import CoarseAligner
from companion.nav.frames import LocalFrame
from companion.nav.navigator import GnssMeasurement
from companion.nav.rotations import euler_to_mat_nb, quat_to_euler, quat_to_mat
from companion.types import FixType, ImuSample

LAT0 = math.radians(40.0)
ALT0 = 1600.0
FRAME = LocalFrame(LAT0, 0.0, ALT0)
G_MPS2 = ins.LocalGravity(LAT0, ALT0).down_mps2(0.0, 0.0)
DEG = math.pi / 180.0


def aligner() -> CoarseAligner:
    return CoarseAligner(1.0, 0.2, 0.5 * DEG, 10.0, 10.0 * DEG, 1.0 * DEG)


def test_levelling_at_rest_matches_the_closed_form() -> None:
    """Noise-free rest at roll 4 deg, pitch -7 deg: roll and pitch from the specific force
    (f_b = C_bn (0, 0, -g)), the gyro bias from the mean rate, the rest specific force's
    magnitude g plus the bias along the vertical."""
    roll, pitch = 4.0 * DEG, -7.0 * DEG
    c_nb = euler_to_mat_nb(roll, pitch, 0.3)
    bias_v = 0.12
    f_b = c_nb.T @ np.array([0.0, 0.0, -(G_MPS2 + bias_v)])
    bg = [0.002, -0.001, 0.003]
    al = aligner()
    for k in range(300):
        al.on_imu(k * 0.01, f_b.tolist(), bg)
    assert al.levelled
    # yaw is unknown: no alignment without motion
    assert al.alignment() is None
    q = al._q
    assert q is not None
    r, p, _ = quat_to_euler(np.array(q))
    assert abs(r - roll) < 1e-9 and abs(p - pitch) < 1e-9
    assert np.allclose(al._bg, bg, atol=1e-12)
    assert al._rest_f is not None
    assert abs(np.linalg.norm(al._rest_f) - (G_MPS2 + bias_v)) < 1e-9


def test_no_levelling_while_moving() -> None:
    al = aligner()
    rng = np.random.default_rng(1)
    for k in range(300):
        f = [rng.normal(0.0, 1.0), rng.normal(0.0, 1.0), -G_MPS2 + rng.normal(0.0, 1.0)]
        al.on_imu(k * 0.01, f, [0.0, 0.0, 0.0])
    assert not al.levelled


class RestThenTurn:
    """Level vehicle: at rest for ``rest_s``, then speeds up smoothly to ``speed_mps`` over
    ``ramp_s`` while turning at ``yaw_rate_radps``; body x along the velocity. Position
    is integrated finely from the exact velocity (errors far below a millimetre)."""

    def __init__(
        self,
        rest_s: float = 5.0,
        ramp_s: float = 4.0,
        speed_mps: float = 5.0,
        yaw_rate_radps: float = 0.25,
        yaw0_rad: float = 2.0,
        duration_s: float = 40.0,
    ) -> None:
        self.rest_s, self.ramp_s, self.v = rest_s, ramp_s, speed_mps
        self.r, self.yaw0 = yaw_rate_radps, yaw0_rad
        dt = 1e-3
        t = np.arange(0.0, duration_s + 1.0, dt)
        vel = np.array([self.vel(float(x)) for x in t])
        pos = np.zeros_like(vel)
        pos[1:] = np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt, axis=0)
        self._t, self._pos = t, pos

    def speed(self, t: float) -> tuple[float, float]:
        """Speed and its rate."""
        s = (t - self.rest_s) / self.ramp_s
        if s <= 0.0:
            return 0.0, 0.0
        if s >= 1.0:
            return self.v, 0.0
        return self.v * 0.5 * (1.0 - math.cos(math.pi * s)), (
            self.v * 0.5 * math.pi / self.ramp_s * math.sin(math.pi * s)
        )

    def yaw(self, t: float) -> tuple[float, float]:
        if t <= self.rest_s:
            return self.yaw0, 0.0
        return self.yaw0 + self.r * (t - self.rest_s), self.r

    def vel(self, t: float) -> np.ndarray:
        v, _ = self.speed(t)
        y, _ = self.yaw(t)
        return np.array([v * math.cos(y), v * math.sin(y), 0.0])

    def pos(self, t: float) -> np.ndarray:
        return np.array([np.interp(t, self._t, self._pos[:, i]) for i in range(3)])

    def imu(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        v, vdot = self.speed(t)
        y, r = self.yaw(t)
        acc_n = np.array(
            [vdot * math.cos(y) - v * r * math.sin(y), vdot * math.sin(y) + v * r * math.cos(y), 0]
        )
        g = ins.LocalGravity(LAT0, ALT0).down_mps2(0.0, 0.0)
        f_n = acc_n - np.array([0.0, 0.0, g])
        c_nb = euler_to_mat_nb(0.0, 0.0, y)
        return c_nb.T @ f_n, np.array([0.0, 0.0, r])


def _run(seed: int, traj: RestThenTurn, duration_s: float = 40.0):
    """Blend without ATTITUDE on a MEMS-like IMU; errors and covariances once a second."""
    rng = np.random.default_rng(seed)
    imu_hz, gnss_hz = 100.0, 5.0
    acc_vrw, gyro_arw = 0.002, 0.003 * DEG
    ba = rng.normal(0.0, 0.02, 3)
    bg = rng.normal(0.0, 0.05 * DEG, 3)
    pos_sig, vel_sig = 0.05, 0.05
    cfg = BlendConfig(
        accel_vrw_mps_rts=acc_vrw,
        gyro_arw_rad_rts=gyro_arw,
        accel_bias_sigma_mps2=0.03,
        gyro_bias_sigma_radps=0.1 * DEG,
        accel_bias_tau_s=math.inf,
        gyro_bias_tau_s=math.inf,
        gnss_error_model="white",
        adaptive=False,
        pos_std_floor_m=(0.001, 0.001),
        vel_std_floor_mps=0.001,
    )
    nav = BlendNavigator(cfg, FRAME)
    events = []
    for k in range(int(duration_s * imu_hz) + 1):
        t = k / imu_hz
        f, w = traj.imu(t)
        acc = f + ba + rng.normal(0.0, acc_vrw * math.sqrt(imu_hz), 3)
        gyro = w + bg + rng.normal(0.0, gyro_arw * math.sqrt(imu_hz), 3)
        events.append((t, 0, ImuSample(t, t, acc, gyro)))
    for k in range(1, int(duration_s * gnss_hz)):
        t = k / gnss_hz
        meas = GnssMeasurement(
            t_s=t,
            pos_ned_m=traj.pos(t) + rng.normal(0.0, pos_sig, 3),
            pos_var_ned_m2=np.full(3, pos_sig**2),
            vel_ned_mps=traj.vel(t) + rng.normal(0.0, vel_sig, 3),
            vel_var_ned_m2ps2=np.full(3, vel_sig**2),
            fix_type=FixType.RTK_FLOAT,
        )
        events.append((t + 0.1, 1, meas))
    events.sort(key=lambda e: (e[0], e[1]))
    t_init = math.nan
    checks: list[tuple[float, np.ndarray, np.ndarray, float, float]] = []
    next_check = 0.0
    gated = 0
    for _, kind, s in events:
        if kind == 0:
            nav.on_imu(s)  # type: ignore[arg-type]
            if nav.initialised and s.t_s >= next_check:  # type: ignore[attr-defined]
                t = s.t_s  # type: ignore[attr-defined]
                next_check = math.floor(t) + 1.0
                st = nav.predict(t)
                assert st is not None
                err = np.concatenate([st.pos_ned_m - traj.pos(t), st.vel_ned_mps - traj.vel(t)])
                p = nav.covariance[0:6, 0:6]
                yaw_true, _ = traj.yaw(t)
                c = quat_to_mat(nav.attitude_q_nb)
                yaw_err = math.remainder(math.atan2(c[1, 0], c[0, 0]) - yaw_true, 2 * math.pi)
                checks.append((t, err, p, yaw_err, math.sqrt(nav.covariance[8, 8])))
        else:
            upd = nav.on_gnss(s)  # type: ignore[arg-type]
            if upd.reason == "init":
                t_init = s.t_s  # type: ignore[attr-defined]
            elif not upd.fused and upd.reason == "gate":
                gated += 1
    return t_init, checks, gated, nav


def test_blend_starts_without_attitude_and_aligns_yaw() -> None:
    """No ATTITUDE at all: the blend levels at rest, finds yaw within seconds of moving off
    (within its own 3 sigma, and to a few degrees), and its gyro bias starts from the rest."""
    traj = RestThenTurn()
    t_init, checks, gated, nav = _run(4, traj)
    assert traj.rest_s < t_init < traj.rest_s + 6.0, t_init
    assert gated == 0
    late = [c for c in checks if c[0] > 30.0]
    assert late
    for _, _, _, yaw_err, yaw_sig in late:
        assert abs(yaw_err) < 3.0 * yaw_sig + 1e-3
        assert abs(yaw_err) < 2.0 * DEG


def test_nees_without_attitude_within_chi2_bounds() -> None:
    """Position+velocity NEES over 20 seeded runs without ATTITUDE, sampled at two epochs
    (10 s after the start and at the end), inside the two-sided 99 % chi-square interval of
    its mean: the alignment's yaw sigma and the filter's covariance are honest."""
    traj = RestThenTurn()
    values: list[float] = []
    gated_total = 0
    for seed in range(20):
        t_init, checks, gated, _ = _run(100 + seed, traj)
        gated_total += gated
        picks = [c for c in checks if abs(c[0] - (t_init + 10.0)) < 0.6 or c[0] > 39.0]
        for _, err, p, _, _ in picks[:2]:
            values.append(float(err @ np.linalg.solve(p, err)))
    n = len(values)
    assert n >= 36
    lo, hi = chi2.ppf([0.005, 0.995], 6 * n) / n
    assert lo < np.mean(values) < hi, (lo, np.mean(values), hi)
    assert gated_total <= 2


def test_restart_keeps_the_blends_own_attitude() -> None:
    """After a restart (the engine's re-initialisation) in motion, with no ATTITUDE and no
    rest to level again, the blend starts at the next fix from its own attitude."""
    traj = RestThenTurn()
    _, checks, _, nav = _run(7, traj, duration_s=20.0)
    assert nav.initialised
    yaw_sigma_before = checks[-1][4]
    t0 = nav.imu_t_s
    nav.reset()
    assert not nav.initialised
    rng = np.random.default_rng(8)
    started = math.nan
    for k in range(1, 201):
        t = t0 + k / 100.0
        f, w = traj.imu(t)
        nav.on_imu(ImuSample(t, t, f + rng.normal(0.0, 0.02, 3), w))
        if k % 20 == 0:
            meas = GnssMeasurement(
                t_s=t - 0.05,
                pos_ned_m=traj.pos(t - 0.05),
                pos_var_ned_m2=np.full(3, 0.05**2),
                vel_ned_mps=traj.vel(t - 0.05),
                vel_var_ned_m2ps2=np.full(3, 0.05**2),
                fix_type=FixType.RTK_FLOAT,
            )
            if nav.on_gnss(meas).reason == "init" and math.isnan(started):
                started = t
    assert started - t0 < 0.5
    yaw_true, _ = traj.yaw(nav.imu_t_s)
    c = quat_to_mat(nav.attitude_q_nb)
    yaw_err = math.remainder(math.atan2(c[1, 0], c[0, 0]) - yaw_true, 2 * math.pi)
    assert abs(yaw_err) < 3.0 * max(yaw_sigma_before, 0.5 * DEG)
    assert math.sqrt(nav.covariance[8, 8]) <= 2.0 * yaw_sigma_before + 1e-9
