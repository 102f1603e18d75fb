"""The simulated path is kinematically consistent: integrating its own IMU signals reproduces it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.nav.rotations import euler_to_quat, quat_mul, quat_to_euler
from companion.sim import make_scenario, simulate
from companion.sim.flight import _make_path
from companion.sim.scenarios import build_script
from companion.sim.trajectory import ScriptBuilder, gravity_down_mps2


def _rot(q: tuple[float, ...], v: tuple[float, ...]) -> tuple[float, float, float]:
    w, x, y, z = q
    r = quat_mul(quat_mul(q, (0.0, *v)), (w, -x, -y, -z))
    return r[1], r[2], r[3]


def _strapdown_rk4(path, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Classical RK4 on (q_nb, v_ned, p_ned) driven by the exact gyro and specific force.

    The signals are evaluated exactly at each step's start, midpoint and end;
    gravity is evaluated at the *integrated* position (not the truth).
    """
    h = t[1] - t[0]
    tt = np.empty(2 * len(t) - 1)
    tt[0::2] = t
    tt[1::2] = 0.5 * (t[:-1] + t[1:])
    st = path.evaluate(tt, with_position=False)
    gyro = st.gyro_b_radps.tolist()
    fb = st.f_b_mps2.tolist()
    frame = path.frame
    s0 = path.evaluate(t[:1])
    q = tuple(euler_to_quat(*s0.euler_rad[0]))
    v = tuple(s0.vel_ned_mps[0])
    p = tuple(s0.pos_ned_m[0])

    g_cache: dict[tuple[float, float], float] = {}

    def grav(pd: tuple[float, ...]) -> float:
        # memoised on a 0.1 m (north) x 1 mm (down) lattice: gravity changes by
        # 3e-6 s^-2 per metre, so the lattice costs < 1e-8 m/s^2
        key = (round(pd[0], 1), round(pd[2], 3))
        if key not in g_cache:
            g_cache[key] = float(gravity_down_mps2(frame, np.array(pd))[0])
        return g_cache[key]

    def deriv(qs, vs, ps, w, f):
        dq = quat_mul(qs, (0.0, *w))
        dq = tuple(0.5 * c for c in dq)
        a = _rot(qs, f)
        return dq, (a[0], a[1], a[2] + grav(ps)), vs

    out_p = np.empty((len(t), 3))
    out_v = np.empty((len(t), 3))
    out_e = np.empty((len(t), 3))
    out_p[0], out_v[0], out_e[0] = p, v, quat_to_euler(np.array(q))
    for k in range(len(t) - 1):
        w0, wm, w1 = gyro[2 * k], gyro[2 * k + 1], gyro[2 * k + 2]
        f0, fm, f1 = fb[2 * k], fb[2 * k + 1], fb[2 * k + 2]
        k1 = deriv(q, v, p, w0, f0)
        q2 = tuple(a + 0.5 * h * b for a, b in zip(q, k1[0], strict=True))
        v2 = tuple(a + 0.5 * h * b for a, b in zip(v, k1[1], strict=True))
        p2 = tuple(a + 0.5 * h * b for a, b in zip(p, k1[2], strict=True))
        k2 = deriv(q2, v2, p2, wm, fm)
        q3 = tuple(a + 0.5 * h * b for a, b in zip(q, k2[0], strict=True))
        v3 = tuple(a + 0.5 * h * b for a, b in zip(v, k2[1], strict=True))
        p3 = tuple(a + 0.5 * h * b for a, b in zip(p, k2[2], strict=True))
        k3 = deriv(q3, v3, p3, wm, fm)
        q4 = tuple(a + h * b for a, b in zip(q, k3[0], strict=True))
        v4 = tuple(a + h * b for a, b in zip(v, k3[1], strict=True))
        p4 = tuple(a + h * b for a, b in zip(p, k3[2], strict=True))
        k4 = deriv(q4, v4, p4, w1, f1)
        q = tuple(
            a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
            for a, b1, b2, b3, b4 in zip(q, k1[0], k2[0], k3[0], k4[0], strict=True)
        )
        n = math.sqrt(sum(c * c for c in q))
        q = tuple(c / n for c in q)
        v = tuple(
            a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
            for a, b1, b2, b3, b4 in zip(v, k1[1], k2[1], k3[1], k4[1], strict=True)
        )
        p = tuple(
            a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
            for a, b1, b2, b3, b4 in zip(p, k1[2], k2[2], k3[2], k4[2], strict=True)
        )
        out_p[k + 1], out_v[k + 1], out_e[k + 1] = p, v, quat_to_euler(np.array(q))
    return out_p, out_v, out_e


@pytest.mark.parametrize(("name", "rate_hz"), [("nominal", 50), ("px4_rotorcraft", 25)])
def test_integrating_imu_signals_reproduces_path(name: str, rate_hz: int) -> None:
    """Strapdown RK4 over the whole flight (nominal: > 10 min) stays within 1 cm of the truth."""
    sc = make_scenario(name, noise=False, wind_ned_mps=(3.0, -4.0, 0.0))
    path, duration = _make_path(sc)
    if name == "nominal":
        assert duration >= 600.0
    t = sc.t_boot0_s + np.arange(int(duration * rate_hz) + 1) / rate_hz
    pos, vel, eul = _strapdown_rk4(path, t)
    truth = path.evaluate(t)
    pos_err = np.linalg.norm(pos - truth.pos_ned_m, axis=1)
    vel_err = np.linalg.norm(vel - truth.vel_ned_mps, axis=1)
    d_eul = np.angle(np.exp(1j * (eul - truth.euler_rad)))
    print(f"{name}: max pos err {pos_err.max():.2e} m, vel {vel_err.max():.2e} m/s")
    assert pos_err.max() < 0.01, f"max position error {pos_err.max():.4f} m"
    assert vel_err.max() < 1e-4
    assert np.abs(d_eul).max() < 1e-7
    # and it is a real flight: it went places
    assert np.ptp(truth.pos_ned_m[:, :2], axis=0).max() > 500.0


def test_derivatives_agree_with_finite_differences() -> None:
    """Velocity = d(position)/dt, acceleration = d(velocity)/dt (central differences, O(h^2))."""
    sc = make_scenario("nominal")
    path, _ = _make_path(sc)
    t = np.linspace(path.t_start_s + 1, path.t_end_s - 1, 4001)
    h = 1e-3
    a, b, c = path.evaluate(t - h), path.evaluate(t), path.evaluate(t + h)
    np.testing.assert_allclose((c.pos_ned_m - a.pos_ned_m) / (2 * h), b.vel_ned_mps, atol=1e-5)
    np.testing.assert_allclose((c.vel_ned_mps - a.vel_ned_mps) / (2 * h), b.acc_ned_mps2, atol=1e-5)


def test_phase_kinematics_match_the_script() -> None:
    """Taxi speeds in 3-10 m/s, 3 deg glide, coordinated bank, flat ground, stops at both ends."""
    sc = make_scenario("nominal", noise=False)
    f = simulate(sc, 1)
    tr = f.truth
    gs = np.hypot(tr.vel_ned_mps[:, 0], tr.vel_ned_mps[:, 1])
    taxi = tr.phase == "taxi"
    assert taxi.any()
    assert 3.0 <= np.percentile(gs[taxi], 50) <= 10.0 and gs[taxi].max() <= 10.0 + 1e-9
    parked = tr.phase == "parked"
    assert np.abs(tr.vel_ned_mps[parked]).max() < 1e-9
    ground = np.isin(tr.phase, ["parked", "taxi", "lineup", "takeoff_roll"])
    assert np.abs(tr.pos_ned_m[ground, 2]).max() < 1e-6
    assert np.abs(tr.pos_ned_m[-1, 2]) < 1e-6  # landed at field height
    # glide: flight-path angle 3 deg during the steady part of the descent
    desc = [(a, b) for p, a, b in f.phases if p == "descent"][0]
    mid = (tr.t_s > desc[0] + 0.6 * (desc[1] - desc[0])) & (tr.t_s < desc[1] - 1.0)
    gamma = np.degrees(np.arctan2(tr.vel_ned_mps[mid, 2], gs[mid]))
    np.testing.assert_allclose(gamma, 3.0, atol=1e-6)
    # coordinated turn: tan(roll) = V * yaw_rate / g in steady cruise turns
    cruise = tr.phase == "cruise"
    rate = tr.gyro_b_radps[cruise, 2] / np.cos(tr.euler_rad[cruise, 0])
    np.testing.assert_allclose(
        np.tan(tr.euler_rad[cruise, 0]), gs[cruise] * rate / 9.80665, atol=1e-3
    )
    assert np.degrees(np.abs(tr.euler_rad[cruise, 0])).max() == pytest.approx(20.0, abs=0.01)


def test_ground_crab_and_wind_crab() -> None:
    """Crab on the ground: heading - track = crab; in the air with wind: nose into the wind."""
    sc = make_scenario("taxi", noise=False, crab_deg=2.5)
    tr = simulate(sc, 1).truth
    moving = np.hypot(tr.vel_ned_mps[:, 0], tr.vel_ned_mps[:, 1]) > 1.0
    track = np.arctan2(tr.vel_ned_mps[moving, 1], tr.vel_ned_mps[moving, 0])
    diff = np.degrees(np.angle(np.exp(1j * (tr.euler_rad[moving, 2] - track))))
    np.testing.assert_allclose(diff, 2.5, atol=1e-9)
    wind = (0.0, 8.0, 0.0)  # from the west, blowing east
    tr = simulate(make_scenario("approach", noise=False, wind_ned_mps=wind), 1).truth
    air = tr.phase == "descent"
    va = tr.vel_ned_mps[air] - np.array(wind)
    np.testing.assert_allclose(
        np.angle(np.exp(1j * (tr.euler_rad[air, 2] - np.arctan2(va[:, 1], va[:, 0])))), 0.0,
        atol=1e-9,
    )  # fmt: skip
    assert np.degrees(np.abs(tr.euler_rad[air, 2])).min() > 10.0  # crabbed into the wind


def test_script_builder_rejects_bad_segments() -> None:
    b = ScriptBuilder(0.0, (0, 0, 0), 0.0)
    with pytest.raises(ValueError):
        b.seg(-1.0, "x")
    with pytest.raises(ValueError):
        b.seg(1.0, "x", bogus=1.0)
    with pytest.raises(ValueError, match="glide"):
        build_script(make_scenario("approach", approach_alt_m=1.0))
