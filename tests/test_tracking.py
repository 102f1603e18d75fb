"""The ground station's tracking channel (companion.nav.tracking): kinematics in closed
form, the dynamic channel and its baselines on a simulated banked turn with truth, rejections."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm, solve_discrete_lyapunov

from companion.nav.tracking import (
    Tracker,
    TrackerConfig,
    _transition,
    acceleration_ned,
    los_to_ned,
    los_velocity_ned,
    ned_to_spherical,
    pointing_error_rad,
    spherical_rates,
)
from companion.sim.scenarios import build_script, make_scenario
from companion.sim.trajectory import gravity_down_mps2

STATION = np.array([-900.0, 1200.0, 0.0])
WHITE_2M = TrackerConfig(
    pos_sigma_m=2.0, pos_gm_sigma_m=0.0, f_sigma_mps2=0.05, att_sigma_rad=math.radians(0.3)
)
"""The filters told the noise these tests add: 2 m white positions, exact attitude and IMU."""


@pytest.fixture(scope="module")
def turn_path():
    sc = make_scenario("cruise_gnss_loss", cruise_turns_deg=(180.0,), bank_deg=30.0)
    b = build_script(sc)
    return b, b.build(sc.frame, sc.wind_ned_mps, fixed_wing=True)


def test_spherical_rates_match_numerical_derivatives(turn_path):
    b, path = turn_path
    turn = [s for s in b.segments if s.end[1] != 0.0][0]
    t = np.array([turn.t1_s + 3.0])
    h = 1e-3
    st = path.evaluate(np.array([t[0] - h, t[0], t[0] + h]))
    sph = np.array([ned_to_spherical(p - STATION) for p in st.pos_ned_m])
    sph[:, 0] = np.unwrap(sph[:, 0])
    first_num = (sph[2] - sph[0]) / (2 * h)
    second_num = (sph[2] - 2 * sph[1] + sph[0]) / h**2
    first, second = spherical_rates(
        st.pos_ned_m[1] - STATION, st.vel_ned_mps[1], st.acc_ned_mps2[1]
    )
    np.testing.assert_allclose(first, first_num, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(second, second_num, rtol=1e-3, atol=1e-7)
    # the velocity back from the angles' rates, and the acceleration from attitude and
    # specific force, are the path's
    az, el, dist = ned_to_spherical(st.pos_ned_m[1] - STATION)
    np.testing.assert_allclose(los_to_ned(az, el, dist), st.pos_ned_m[1] - STATION, atol=1e-9)
    np.testing.assert_allclose(los_velocity_ned(az, el, dist, first), st.vel_ned_mps[1], atol=1e-6)
    g = gravity_down_mps2(path.frame, st.pos_ned_m[1:2])[0]
    acc = acceleration_ned(st.mat_nb[1], st.f_b_mps2[1], g)
    np.testing.assert_allclose(acc, st.acc_ned_mps2[1], atol=1e-9)
    assert np.linalg.norm(acc[:2]) > 4.0  # a 30 deg bank: about 0.58 g across the track


def _track(
    path, t0, t1, model, rate_hz=2.0, seed=3, loss=None, cfg=WHITE_2M, f_bias=None, gm_m=0.0
):
    rng = np.random.default_rng(seed)
    tracker = Tracker(model, cfg)
    t_tel = np.arange(t0, t1, 1.0 / rate_hz)
    st = path.evaluate(t_tel)
    g = gravity_down_mps2(path.frame, st.pos_ned_m)
    errs, sigmas, nees = [], [], []
    wander = np.zeros(3)
    for i, t in enumerate(t_tel):
        rel = st.pos_ned_m[i] - STATION
        est = tracker.estimate(float(t))  # predicted to the sample, before it is used
        if est is not None and t > t0 + 10.0:
            errs.append(pointing_error_rad(est, rel))
            sigmas.append(est.pointing_sigma_rad)
            e = est.pos_ned_m - rel
            nees.append(float(e @ np.linalg.solve(est.pos_cov_m2, e)))
        if gm_m > 0.0:  # the reported positions' slowly wandering error (tau 30 s)
            phi = math.exp(-1.0 / (rate_hz * 30.0))
            wander = phi * wander + rng.normal(0.0, gm_m * math.sqrt(1.0 - phi * phi), 3)
        if loss is not None and loss[0] <= t < loss[1]:
            continue
        tracker.position(float(t), rel + wander + rng.normal(0.0, cfg.pos_sigma_m, 3))
        f_b = st.f_b_mps2[i] if f_bias is None else st.f_b_mps2[i] + f_bias
        tracker.acceleration(float(t), acceleration_ned(st.mat_nb[i], f_b, g[i]), st.mat_nb[i])
    tracker.nees = np.array(nees)
    return np.array(errs), np.array(sigmas), tracker


def test_s2_tracks_a_banked_turn_better_than_singer_and_cv(turn_path):
    b, path = turn_path
    turn = [s for s in b.segments if s.end[1] != 0.0][0]
    t0, t1 = turn.t0_s - 20.0, turn.t1_s + 40.0
    rms = {}
    for model in ("dynamic", "singer", "cv"):
        errs, sigmas, trk = _track(path, t0, t1, model)
        rms[model] = float(np.sqrt(np.mean(errs**2)))
        if model == "dynamic":
            assert trk.accelerations == trk.positions
            # its stated uncertainty covers its error (2-D pointing error: 3 sigma)
            assert np.mean(errs <= 3.0 * sigmas) > 0.95
        else:
            assert trk.accelerations == 0
    assert rms["dynamic"] < 0.7 * rms["singer"] and rms["singer"] < rms["cv"], rms


def test_jerk_model_keeps_singers_manoeuvre_amplitude():
    """The dynamic channel's acceleration is driven by a first-order Markov jerk (roll
    response τ_j) instead of white noise; its stationary 1σ is still Singer's σ_m, so
    without z2 (a loss) it predicts the same manoeuvre amplitude as Singer's model."""
    cfg = TrackerConfig()
    assert cfg.jerk_tau_s > 0.0
    f, q = _transition("dynamic", 0.5, cfg)
    a_j = np.r_[6, 9]  # north acceleration and jerk
    p = solve_discrete_lyapunov(f[np.ix_(a_j, a_j)], q[np.ix_(a_j, a_j)])
    assert math.sqrt(p[0, 0]) == pytest.approx(cfg.singer_sigma_mps2, rel=1e-6)
    assert math.sqrt(p[1, 1]) == pytest.approx(cfg.jerk_sigma_mps3, rel=1e-6)
    # without the jerk state the channel's motion model is Singer's
    fs, qs = _transition("singer", 0.5, cfg)
    f0, q0 = _transition("dynamic", 0.5, dataclasses.replace(cfg, jerk_tau_s=0.0))
    np.testing.assert_allclose(f0[:9, :9], fs[:9, :9])
    np.testing.assert_allclose(q0[:9, :9], qs[:9, :9])


@pytest.mark.parametrize("dt", [0.3, 2.0, 12.0, 40.0])
def test_jerk_model_discretisation_holds_over_long_gaps(dt):
    """Q of the jerk model equals ∫ e^{As} G Gᵀ e^{Aᵀs} ds and stays positive definite
    over a telemetry loss (van Loan's block exponential alone went indefinite beyond
    about 5 s: negative variances, then a z2 noise estimate thrown to its cap)."""
    cfg = TrackerConfig()
    tau_a, tau_j, sig_j = cfg.singer_tau_s, cfg.jerk_tau_s, cfg.jerk_sigma_mps3
    a_c = np.array(
        [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, -1 / tau_a, 1], [0, 0, 0, -1 / tau_j]], dtype=float
    )
    g = np.array([[0.0], [0.0], [0.0], [sig_j * math.sqrt(2.0 / tau_j)]])
    q_true, _ = quad_vec(lambda s: expm(a_c * s) @ g @ g.T @ expm(a_c * s).T, 0.0, dt, epsrel=1e-10)
    f, q = _transition("dynamic", dt, cfg)
    axis = np.r_[0, 3, 6, 9]  # north r, v, a, j
    np.testing.assert_allclose(f[np.ix_(axis, axis)], expm(a_c * dt), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(q[np.ix_(axis, axis)], q_true, rtol=1e-6, atol=1e-9)
    assert np.linalg.eigvalsh(q).min() >= 0.0


def test_z2_noise_estimate_survives_a_long_loss(turn_path):
    """After 12 s without telemetry the first samples do not throw the learnt z2 noise
    to its cap (it stays near the sensor model), and the prediction's σ is finite."""
    b, path = turn_path
    turn = [s for s in b.segments if s.end[1] != 0.0][0]
    loss = (turn.t0_s - 5.0, turn.t0_s + 7.0)
    errs, sigmas, trk = _track(path, turn.t0_s - 40.0, turn.t1_s + 10.0, "dynamic", loss=loss)
    assert np.all(np.isfinite(sigmas)) and np.all(sigmas > 0.0)
    assert np.all(np.diag(trk.kf.P) >= 0.0)  # e: zero, these positions do not wander
    assert np.all(np.sqrt(trk.acc_var_mps2) < 3.0 * WHITE_2M.acc_sigma_floor_mps2)
    assert np.mean(errs <= 3.0 * sigmas) > 0.95


def test_exact_accelerations_approach_a_known_input_filter(turn_path):
    """With exact attitude and IMU the dynamic channel is at least 2.5× better than
    Singer through a banked turn. A white-driven acceleration (the Brownian bridge
    between two z2 samples) and a fast-wandering z2 bias left it at 2.26×."""
    b, path = turn_path
    turn = [s for s in b.segments if s.end[1] != 0.0][0]
    t0, t1 = turn.t0_s - 20.0, turn.t1_s + 40.0
    rms = {}
    for model in ("dynamic", "singer"):
        errs, sigmas, trk = _track(path, t0, t1, model, rate_hz=2.0)
        rms[model] = float(np.sqrt(np.mean(errs**2)))
        assert np.mean(errs <= 3.0 * sigmas) > 0.95
        assert 1.5 < float(np.mean(trk.nees)) < 4.0
    assert rms["singer"] > 2.5 * rms["dynamic"], rms


def _known_input_sigma_m(dt: float, pos_sigma_m: float, acc_sigma_mps2: float) -> float:
    """Steady-state 1σ of the position of a filter told the acceleration (white error
    ``acc_sigma_mps2`` per sample, held over ``dt``) and the positions, per axis (the
    Riccati recursion of r, v with the acceleration as a known input)."""
    f = np.array([[1.0, dt], [0.0, 1.0]])
    g = np.array([[0.5 * dt * dt], [dt]])
    q = g @ g.T * acc_sigma_mps2**2
    h = np.array([[1.0, 0.0]])
    p = np.eye(2) * 100.0
    for _ in range(5000):
        p = f @ p @ f.T + q
        k = p @ h.T / (h @ p @ h.T + pos_sigma_m**2)
        p = (np.eye(2) - k @ h) @ p
    return math.sqrt(p[0, 0])


@pytest.mark.parametrize("rate_hz, margin", [(1.0, 1.25), (5.0, 1.1)])
def test_dynamic_channel_reaches_the_known_input_filter(rate_hz, margin):
    """In steady flight with exact telemetry (z2 at its noise floor) the dynamic
    channel's position σ is within a margin of the known-input filter's: z2 carries
    nearly all the acceleration's information. With Singer's white-driven
    acceleration and the faster bias walk it was 1.43× (1 Hz) and 1.40× (5 Hz) above."""
    trk = Tracker("dynamic", WHITE_2M)
    t = 0.0
    for k in range(int(600 * rate_hz)):
        t = k / rate_hz
        assert trk.position(t, np.array([1000.0 + 40.0 * t, 500.0, -300.0]))
        assert trk.acceleration(t, np.zeros(3), np.eye(3))  # level, heading north
    est = trk.estimate(t)
    assert est is not None
    bound = _known_input_sigma_m(1.0 / rate_hz, WHITE_2M.pos_sigma_m, WHITE_2M.acc_sigma_floor_mps2)
    sigma = np.sqrt(np.diag(est.pos_cov_m2))
    assert np.all(sigma >= bound), (sigma, bound)
    assert np.all(sigma < margin * bound), (sigma, bound)


def test_dynamic_channel_uses_the_imu_samples_between_positions():
    """A link that carries ATTITUDE and the IMU faster than the positions (10 per position
    at 1 Hz): every sample is an update, so the velocity change between two positions is
    known to z2's noise /√10 and the position σ falls below the one-sample known-input
    filter's, within 1.25× of the ten-sample one's."""
    one, ten = Tracker("dynamic", WHITE_2M), Tracker("dynamic", WHITE_2M)
    t = 0.0
    for k in range(300):
        t = float(k)
        for trk, n in ((one, 1), (ten, 10)):
            assert trk.position(t, np.array([1000.0 + 40.0 * t, 500.0, -300.0]))
            for m in range(n):
                assert trk.acceleration(t + m / n, np.zeros(3), np.eye(3))
    floor = WHITE_2M.acc_sigma_floor_mps2
    bound_1 = _known_input_sigma_m(1.0, WHITE_2M.pos_sigma_m, floor)
    bound_10 = _known_input_sigma_m(1.0, WHITE_2M.pos_sigma_m, floor / math.sqrt(10.0))
    sig_1 = np.sqrt(np.diag(one.kf.P[0:3, 0:3]))
    sig_10 = np.sqrt(np.diag(ten.kf.P[0:3, 0:3]))
    assert np.all(sig_10 < bound_1) and np.all(sig_1 > bound_1), (sig_1, sig_10, bound_1)
    assert np.all(sig_10 >= bound_10) and np.all(sig_10 < 1.25 * bound_10), (sig_10, bound_10)
    assert ten.accelerations == 10 * ten.positions


def test_dynamic_channel_is_consistent_and_learns_its_observation_noise(turn_path):
    """A body-frame accelerometer bias is estimated through the turn, z2's noise is
    learnt from its innovations, and the filter's NIS and NEES are those of a
    consistent filter (3 degrees of freedom) with wandering reported positions."""
    b, path = turn_path
    turn = [s for s in b.segments if s.end[1] != 0.0][0]
    bias = np.array([0.3, -0.2, 0.15])
    cfg = TrackerConfig(pos_sigma_m=0.7, pos_gm_sigma_m=1.5, f_sigma_mps2=0.05)
    _, _, trk = _track(
        path, turn.t0_s - 30.0, turn.t1_s + 60.0, "dynamic", cfg=cfg, f_bias=bias, gm_m=1.5
    )
    np.testing.assert_allclose(trk.bias_b_mps2, bias, atol=0.1)
    # exact attitude and IMU: z2's noise falls to its floor (0.05 m/s² and 0.5 deg: 0.095)
    assert np.all(np.sqrt(trk.acc_var_mps2) < 0.2)
    nis = trk.nis_position / (trk.positions - 1)
    assert 2.0 < nis < 4.0, nis
    assert 1.5 < float(np.mean(trk.nees)) < 5.0, float(np.mean(trk.nees))
    # noisy IMU samples (1 m/s² per axis): the estimated noise rises to them (a little below:
    # what the manoeuvre model's excess predicted variance leaves) and z2's NIS stays ~3
    rng = np.random.default_rng(5)
    noisy = Tracker("dynamic", cfg)
    st = path.evaluate(np.arange(turn.t0_s - 30.0, turn.t1_s + 30.0, 0.5))
    g = gravity_down_mps2(path.frame, st.pos_ned_m)
    for i, t in enumerate(st.t_s):
        noisy.position(float(t), st.pos_ned_m[i] - STATION + rng.normal(0.0, 0.7, 3))
        f_b = st.f_b_mps2[i] + rng.normal(0.0, 1.0, 3)
        noisy.acceleration(float(t), acceleration_ned(st.mat_nb[i], f_b, g[i]), st.mat_nb[i])
    assert np.all((np.sqrt(noisy.acc_var_mps2) > 0.4) & (np.sqrt(noisy.acc_var_mps2) < 1.5))
    assert 2.0 < noisy.nis_acceleration / noisy.accelerations < 4.5


def test_prediction_through_a_telemetry_loss_grows_its_uncertainty(turn_path):
    b, path = turn_path
    turn = [s for s in b.segments if s.end[1] != 0.0][0]
    loss = (turn.t1_s + 5.0, turn.t1_s + 10.0)
    _, _, trk = _track(path, turn.t0_s - 20.0, loss[0], "dynamic")
    e0 = trk.estimate(loss[0])
    e1 = trk.estimate(loss[1])
    assert e0 is not None and e1 is not None
    assert e1.since_position_s > e0.since_position_s + 4.9
    assert e1.pointing_sigma_rad > 2.0 * e0.pointing_sigma_rad
    truth = path.evaluate(np.array([loss[1]])).pos_ned_m[0] - STATION
    assert pointing_error_rad(e1, truth) < 3.0 * e1.pointing_sigma_rad
    assert pointing_error_rad(e1, truth) < math.radians(1.5)


def test_bad_samples_are_counted_not_fatal():
    trk = Tracker("dynamic")
    assert trk.estimate(0.0) is None
    assert not trk.acceleration(0.0, np.zeros(3))  # before any position: ignored
    assert trk.position(1.0, np.array([1000.0, -1.0, -100.0]))
    assert not trk.position(2.0, np.array([np.nan, 0.0, 0.0]))
    assert not trk.position(0.5, np.array([1000.0, 1.0, -100.0]))  # older than the filter
    assert not trk.position(3.0, np.array([1.0, 1.0, 0.0]))  # on the station
    assert not trk.acceleration(3.0, np.array([np.inf, 0.0, 0.0]))
    assert trk.rejected == 4
    # across north the azimuth wraps, it does not swing the long way round
    assert trk.position(2.0, np.array([1000.0, 1.0, -100.0]))
    est = trk.estimate(2.0)
    assert est is not None and abs(est.az_rad) < math.radians(1.0)
    with pytest.raises(ValueError):
        Tracker("kalman")  # type: ignore[arg-type]
