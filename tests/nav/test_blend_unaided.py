"""The autopilot's attitude through a GNSS gap it shares: modelled unaided (no pull back,
turned by its rates' bias), in closed form and on a seeded simulated flight with truth."""

from __future__ import annotations

import math
from unittest import mock

import numpy as np
from scipy.stats import chi2

from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.blend.error_model import ErrorModel, gm_psd
from companion.nav.blend.unaided import heading_sensitivity
from companion.nav.rotations import euler_to_mat_nb
from companion.types import AttitudeSample, ImuSample
from tests.nav.test_blend import FRAME, SimSpec, config_for, simulate

_DEG = math.pi / 180.0


def _attitude_var_after(
    unaided: bool, t_s: float, p0: float, bias_var: float, *, tilt: bool = False
) -> np.ndarray:
    """The attitude error's variance (3,) after ``t_s`` at rest (no specific force), level,
    from ``p0`` and the gyro-bias variance ``bias_var`` (uncorrelated)."""
    cfg = BlendConfig(cov_discretisation="van_loan")
    model = ErrorModel(cfg)
    model.reset(np.full(3, cfg.accel_vrw_mps_rts**2))
    model.set_unaided(unaided, tilt=tilt)
    p = np.zeros((18, 18))
    p[6:9, 6:9] = np.eye(3) * p0
    p[12:15, 12:15] = np.eye(3) * bias_var
    dt = 0.1
    for _ in range(int(round(t_s / dt))):
        phi, qd = model.transition(dt, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
        p = phi @ p @ phi.T + qd
    return np.diag(p)[6:9]


def test_unaided_attitude_error_grows_as_a_walk_plus_the_rates_bias_closed_form() -> None:
    """Unaided, the heading error is psi0 + w + b t, so its variance is p0 + q t +
    sigma_b^2 t^2 (q the Gauss-Markov driving noise, 2 sigma^2 / tau; the bias's own slow
    walk added); the tilt, and every axis aided, relax to sigma^2 as Gauss-Markov
    processes, and the bias does not reach them. With the tilt unaided too (nothing but
    GNSS levelled it), every axis grows as the heading."""
    cfg = BlendConfig()
    sig = np.array(cfg.att_err_sigma_rad)
    tau = cfg.att_err_tau_s
    p0 = (0.3 * _DEG) ** 2
    b_var = (0.02 * _DEG) ** 2
    t = 30.0
    q = 2.0 * sig**2 / tau
    # the bias's Gauss-Markov walk over t, integrated twice into the attitude: q_b t^3 / 3
    q_b = gm_psd(cfg.gyro_bias_sigma_radps, cfg.gyro_bias_tau_s)
    decay = math.exp(-t / cfg.gyro_bias_tau_s)  # the bias's own correlation over t
    bias_part = b_var * (cfg.gyro_bias_tau_s * (1.0 - decay)) ** 2
    heading = p0 + q[2] * t + bias_part + q_b * t**3 / 3.0
    relax = math.exp(-2.0 * t / tau)
    gauss_markov = p0 * relax + sig**2 * (1.0 - relax)
    got = _attitude_var_after(True, t, p0, b_var)
    np.testing.assert_allclose(got[2], heading, rtol=2e-3)
    np.testing.assert_allclose(got[:2], gauss_markov[:2], rtol=2e-3)  # tilt: still aided
    aided = _attitude_var_after(False, t, p0, b_var)
    np.testing.assert_allclose(aided, gauss_markov, rtol=2e-3)
    # the tilt unaided too (nothing levels it): every axis as the heading
    walk = p0 + q * t + bias_part + q_b * t**3 / 3.0
    np.testing.assert_allclose(_attitude_var_after(True, t, p0, b_var, tilt=True), walk, rtol=2e-3)
    # and the tilt flag alone, aided, changes nothing
    np.testing.assert_allclose(
        _attitude_var_after(False, t, p0, b_var, tilt=True), gauss_markov, rtol=2e-3
    )


def _fly(unaided_model: bool, seed: int, *, pulled: bool = False) -> tuple[float, float, bool]:
    """A turning flight whose autopilot's body rates carry a bias about down that its
    GNSS-aided attitude does not show (its filter corrects it); through a 20 s gap its
    attitude is unaided and its heading turns with that bias. ``pulled``: its rates are
    true and its heading is pulled 1 deg off over the gap's first 8 s instead (a compass
    in a turn), which only its departure from its rates shows. Returns the worst
    horizontal error, the worst position NEES and whether the unaided model was on at the
    gap's end."""
    spec = SimSpec(duration_s=50.0, outage=(25.0, 45.0))
    sim = simulate(spec, seed)
    bias_radps = 0.0 if pulled else 0.05 * _DEG  # 180 deg/h: its yaw drifts 1 deg in the gap
    t_gap = 25.0

    def heading_error(t_s: float) -> float:
        if pulled:
            return 1.0 * _DEG * min(max(t_s - t_gap, 0.0) / 8.0, 1.0)
        return bias_radps * (t_s - t_gap) if t_s >= t_gap else 0.0

    nav = BlendNavigator(config_for(spec, mode="attitude_aided", adaptive=False), FRAME)
    worst, worst_nees, on_at_end = 0.0, 0.0, False
    for s in sim.samples:
        in_gap = t_gap + 0.5 <= s.t_s < 45.0
        if unaided_model:
            nav.attitude_unaided(in_gap)
        if isinstance(s, AttitudeSample):
            # a bias about down (in body axes here), so that it turns the heading alone
            c_nb = euler_to_mat_nb(s.roll_rad, s.pitch_rad, s.yaw_rad)
            rates = s.rate_b_radps + c_nb.T @ np.array([0.0, 0.0, bias_radps])
            yaw = s.yaw_rad + heading_error(s.t_s)
            nav.on_attitude(
                AttitudeSample(s.t_s, s.t_rx_s, s.roll_rad, s.pitch_rad, yaw, rates), 0.0
            )
        elif isinstance(s, ImuSample):
            nav.on_imu(s)
            if 26.0 <= s.t_s < 45.0 and nav.initialised:
                on_at_end = nav.attitude_unaided_flag
                st = nav.predict(s.t_s)
                assert st is not None
                err = (st.pos_ned_m - spec.traj.pos(s.t_s))[:2]
                worst = max(worst, float(np.hypot(err[0], err[1])))
                cov = st.pos_cov_ned_m2[:2, :2]
                worst_nees = max(worst_nees, float(err @ np.linalg.solve(cov, err)))
        else:
            nav.on_gnss(s)
    return worst, worst_nees, on_at_end


def test_unaided_autopilot_attitude_is_covered_through_the_gap() -> None:
    """Simulated truth: the autopilot's heading turns 1 deg over the gap with its rates'
    bias. Modelled unaided (the bias bounded from how its attitude strayed from its rates
    before), the horizontal NEES stays within chi-square(2) at 99.9 % throughout in three seeds;
    modelled aided (Gauss-Markov, 0.5 deg), the same errors are outside their covariance
    (NEES 44, 11, 12 against 5.8, 3.9, 4.2)."""
    gate = chi2.ppf(0.999, 2)
    worst_aided = 0.0
    for seed in (1, 2, 3):
        err_u, nees_u, on = _fly(True, seed)
        err_a, nees_a, _ = _fly(False, seed)
        assert on
        assert err_u > 1.5  # the heading drift really moves the position (1.2 m without)
        assert abs(err_u - err_a) < 0.05 * err_a  # the model changes the covariance only
        assert nees_u < gate, (seed, nees_u)
        assert nees_a > 1.5 * nees_u, (seed, nees_a, nees_u)
        worst_aided = max(worst_aided, nees_a)
    assert worst_aided > 2.0 * gate


def test_a_departure_counts_on_the_velocity_it_turned_closed_form() -> None:
    """A heading error present since the gap's start, propagated through the unaided error
    model over a level turn (numerical integration), turns position and velocity by
    :func:`heading_sensitivity` of the velocity change and the displacement beyond the
    start's velocity."""
    model = ErrorModel(BlendConfig(cov_discretisation="van_loan"))
    model.reset(np.zeros(3))
    model.set_unaided(True)
    p = np.zeros((18, 18))
    p[8, 8] = 1.0
    speed, rate, dt = 30.0, 6.0 * _DEG, 0.01
    vel0 = np.array([speed, 0.0])
    pos, vel, t = np.zeros(2), vel0.copy(), 0.0
    for _ in range(1500):  # 15 s: a 90 deg turn
        yaw = rate * (t + 0.5 * dt)
        f_ned = (-speed * rate * math.sin(yaw), speed * rate * math.cos(yaw), -9.81)
        q_nb = (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))
        phi, qd = model.transition(dt, f_ned, q_nb)
        p = phi @ p @ phi.T
        pos = pos + vel * dt + 0.5 * np.array(f_ned[:2]) * dt**2
        vel = vel + np.array(f_ned[:2]) * dt
        t += dt
    dv = vel - vel0
    dq = pos - vel0 * t
    expected = heading_sensitivity((dv[0], dv[1]), (dq[0], dq[1]))
    got = (p[0, 8], p[1, 8], p[3, 8], p[4, 8])
    np.testing.assert_allclose(got, expected, rtol=1e-3, atol=1e-6)
    assert abs(dv[1]) > 20.0  # the turn really changed the velocity


def test_a_heading_pulled_in_the_gaps_turn_is_covered() -> None:
    """Simulated truth: the autopilot's rates are true and its heading is pulled 1 deg off
    in the gap's first 8 s. The departure counted as a heading error present since the
    gap's start keeps the position NEES within chi-square(2) at 99.9 % in three seeds;
    counted on the heading alone (from when it was seen, smoothed), the turn it happened
    in is lost and the NEES is larger in every seed (measured: 5.3, 3.3, 4.1 against 13.2,
    6.2, 7.0)."""
    gate = chi2.ppf(0.999, 2)
    for seed in (1, 2, 3):
        err, nees, on = _fly(True, seed, pulled=True)
        assert on
        assert err > 1.5  # the pulled heading really moves the position
        with mock.patch("companion.nav.blend.filter.heading_sensitivity", return_value=(0.0,) * 4):
            err_h, nees_h, _ = _fly(True, seed, pulled=True)
        assert err_h == err  # the covariance alone changes
        assert nees < gate, (seed, nees)
        assert nees_h > 1.5 * nees, (seed, nees_h, nees)


def test_unaided_model_only_in_attitude_aided_mode_and_restores_the_bias() -> None:
    """Strapdown or held attitudes are not the autopilot's attitude taken: the flag is
    kept but nothing changes; leaving a gap restores the gyro bias in use."""
    spec = SimSpec(duration_s=12.0)
    sim = simulate(spec, 4)
    nav = BlendNavigator(config_for(spec, mode="strapdown", adaptive=False), FRAME)
    aided = BlendNavigator(config_for(spec, mode="attitude_aided", adaptive=False), FRAME)
    for s in sim.samples:
        for n in (nav, aided):
            if isinstance(s, AttitudeSample):
                n.on_attitude(s, 0.0)
            elif isinstance(s, ImuSample):
                n.on_imu(s)
            else:
                n.on_gnss(s)
    p_before = nav.covariance
    nav.attitude_unaided(True)
    assert nav.attitude_unaided_flag
    np.testing.assert_array_equal(nav.covariance, p_before)
    bg_before = aided.biases[1].copy()
    aided.attitude_unaided(True)
    p = aided.covariance
    assert np.all(np.diag(p)[12:15] > 0.0)
    assert np.all(p[12:15, 0:12] == 0.0)
    aided.hold_attitude(True)  # the rates carry it: the strapdown model takes over
    aided.hold_attitude(False)
    aided.attitude_unaided(False)
    np.testing.assert_array_equal(aided.biases[1], bg_before)
