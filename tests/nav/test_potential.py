"""Tests of the position-potential filter (S0): closed form, fit, fix test, covariance."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import solve_ivp

from companion.nav.potential import (
    NAME_ALPHA,
    NAME_G,
    PotentialConfig,
    PotentialFilter,
    combine_predictions,
    field_sums,
    propagate_axis,
    propagate_state,
    replay_cost,
    transition_axis,
)

# --------------------------------------------------------------------------- helpers


def _ode_fundamental(ga: float, alpha: float, t_end: float, t_eval: np.ndarray) -> np.ndarray:
    """Columns of the fundamental matrix of ü = −G·A e^{−αt} u by DOP853 (rows: u1, u̇1, u2, u̇2)."""

    def rhs(t: float, y: np.ndarray) -> list[float]:
        k = ga * np.exp(-alpha * t)
        return [y[1], -k * y[0], y[3], -k * y[2]]

    sol = solve_ivp(
        rhs, (0.0, t_end), [1.0, 0.0, 0.0, 1.0], method="DOP853", rtol=1e-13, atol=1e-15,
        t_eval=t_eval,
    )  # fmt: skip
    assert sol.success
    return sol.y


ALPHAS = [0.0, 1e-4, 1e-2, 0.5, 3.0, 10.0]
GAS = [0.0, 1e-6, 1e-2, 1.0, 100.0, 1e4]


@pytest.mark.parametrize("alpha", ALPHAS)
def test_closed_form_matches_numerical_integration(alpha: float) -> None:
    # The grid spans every branch: oscillator (α = 0), Hankel form (s, s0 ≥ 200,
    # e.g. α = 1e-4 with G·A = 1e4 gives s0 = 2e6), mixed large/mid, scipy,
    # series for tiny s0 (α = 10, G·A = 1e-6) and for an underflowing s (α t = 200).
    for ga in GAS:
        omega = np.sqrt(ga)
        t_end = 20.0 if omega * 20.0 <= 300.0 else 300.0 / omega
        ts = np.array([0.0, 0.013, 0.37, 1.0, 2.0, 5.0, 20.0])
        ts = ts[ts <= t_end]
        if ts[-1] < t_end:
            ts = np.append(ts, t_end)
        y = _ode_fundamental(ga, alpha, t_end, ts)
        for u0, v0 in [(-50.0, -80.0), (3.0, 0.5), (100.0, 100.0), (0.0, 1.0)]:
            u, ud = propagate_axis(u0, v0, ga, alpha, ts)
            u_ref = y[0] * u0 + y[2] * v0
            ud_ref = y[1] * u0 + y[3] * v0
            np.testing.assert_allclose(u, u_ref, rtol=0, atol=1e-6, err_msg=f"ga={ga}")
            np.testing.assert_allclose(ud, ud_ref, rtol=0, atol=1e-6, err_msg=f"ga={ga}")


def test_limits_are_continuous() -> None:
    t = np.linspace(0.0, 30.0, 31)
    # α → 0: oscillator
    ga = 2.5
    w = np.sqrt(ga)
    for alpha in (1e-10, 1e-12, 1e-15):  # phase drift ω α t²/4 < 1e-7 rad
        u, ud = propagate_axis(7.0, -3.0, ga, alpha, t)
        np.testing.assert_allclose(u, 7 * np.cos(w * t) - 3 * np.sin(w * t) / w, atol=1e-6)
        np.testing.assert_allclose(ud, -7 * w * np.sin(w * t) - 3 * np.cos(w * t), atol=1e-6)
    # G·A → 0: coasting
    for ga_small in (1e-14, 1e-300):
        u, ud = propagate_axis(7.0, -3.0, ga_small, 2.0, t)
        np.testing.assert_allclose(u, 7 - 3 * t, atol=1e-6)
        np.testing.assert_allclose(ud, -3.0, atol=1e-6)
    # α t → ∞: the field is gone, the particle coasts with a finite velocity
    u, ud = propagate_axis(1.0, 0.0, 1.0, 10.0, [1e3, 1e4])
    assert np.all(np.isfinite(u)) and np.all(np.isfinite(ud))
    np.testing.assert_allclose(ud[0], ud[1], atol=1e-12)
    # t = 0 is the identity everywhere
    ga_g, al_g = np.meshgrid(GAS, ALPHAS)
    w1, w2, w1d, w2d = transition_axis(ga_g, al_g, 0.0)
    np.testing.assert_allclose(w1, 1.0, atol=1e-13)
    np.testing.assert_allclose(w2, 0.0, atol=1e-13)
    np.testing.assert_allclose(w1d, 0.0, atol=1e-10)
    np.testing.assert_allclose(w2d, 1.0, atol=1e-13)


def test_transition_rejects_bad_input() -> None:
    with pytest.raises(ValueError):
        transition_axis(1.0, 1.0, -0.1)
    with pytest.raises(ValueError):
        transition_axis(-1.0, 1.0, 0.1)
    with pytest.raises(ValueError):
        transition_axis(1.0, np.nan, 0.1)


def test_large_alpha_w_form_equals_general_form() -> None:
    # S0: for large α only the newest fix matters and
    # k(t) = k_0n + W1(t) Δk_n + W2(t) k̇_n with A_k ≈ 2 p_kn.
    rng = np.random.default_rng(3)
    n = 8
    t_src = np.arange(n) * 2.0  # S0's 2-s steps
    pos_src = np.cumsum(rng.normal(0.0, 50.0, (n, 3)), axis=0)
    var = np.array([0.5, 0.8, 2.0])
    p_src = np.tile(1.0 / var, (n, 1))
    alpha, g = 12.0, 0.35
    particle = pos_src[-1] + np.array([1.5, -0.7, 2.2])  # Δk_n
    vel = np.array([62.0, -4.0, 3.1])
    a, b = field_sums(t_src, pos_src, p_src, alpha, t_src[-1])
    ts = np.linspace(0.0, 2.0, 9)
    for t in ts:
        general, _ = propagate_state(particle, vel, a, b, g, alpha, t)
        w1, w2, _, _ = transition_axis(g * 2.0 / var, alpha, t)
        w_form = pos_src[-1] + w1 * (particle - pos_src[-1]) + w2 * vel
        np.testing.assert_allclose(general, w_form, atol=1e-6)
    # with a single source the two are the same for any α
    a1, b1 = field_sums(t_src[-1:], pos_src[-1:], p_src[-1:], 0.3, t_src[-1])
    general, _ = propagate_state(particle, vel, a1, b1, g, 0.3, 1.7)
    w1, w2, _, _ = transition_axis(g * 2.0 / var, 0.3, 1.7)
    np.testing.assert_allclose(general, pos_src[-1] + w1 * (particle - pos_src[-1]) + w2 * vel)


# --------------------------------------------------------------------------- model data


def _model_track(
    alpha: float, g: float, n: int = 40, dt: float = 0.25
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fixes that are exactly the model particle's positions (sources = the fixes)."""
    var = np.array([1.0, 1.0, 4.0])
    p = 1.0 / var
    pos = np.array([0.0, 0.0, -300.0])
    vel = np.array([60.0, 5.0, 3.0])
    ts: list[float] = []
    ps: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    for i in range(n):
        if i > 0:
            a, b = field_sums(np.array(ts), np.vstack(ps), np.tile(p, (len(ts), 1)), alpha, ts[-1])
            pos, vel = propagate_state(pos, vel, a, b, g, alpha, dt)
        ts.append(i * dt)
        ps.append(pos.copy())
        vs.append(vel.copy())
    return np.array(ts), np.vstack(ps), np.vstack(vs), var


# S0's stable-descent and descent-rate-change values and two stiffer fields.
# Known limit (not hidden): for α ≲ 1.5 1/s the global valley of the objective
# is narrower than the seeding grid and the population can settle in the broad
# basin at the α upper bound; those cases are not claimed here.
@pytest.mark.parametrize(("alpha", "g"), [(2.84, 0.35), (3.82, 0.54), (8.0, 2.0), (6.0, 20.0)])
def test_fit_recovers_model_alpha_and_g(alpha: float, g: float) -> None:
    ts, pos, vel, var = _model_track(alpha, g)
    cfg = PotentialConfig(
        window_s=20.0, velocity_mode="carried", alpha0_ps=1.0, g0_m2ps2=1.0,
        de_maxiter=60, de_popsize=15, de_tol=1e-8, seed=11,
    )  # fmt: skip
    f = PotentialFilter(cfg)
    for i in range(ts.size):
        res = f.add_fix(ts[i], pos[i], var, vel[i] if i == 0 else None, force=True, refit=False)
        assert res.accepted
    # the objective is zero at the truth and the optimiser finds it
    out = f.refit(force=True)
    assert out is not None
    assert f.alpha_ps == pytest.approx(alpha, rel=1e-3)
    assert f.g_m2ps2 == pytest.approx(g, rel=1e-3)
    assert f.last_fit_cost_m2 is not None and f.last_fit_cost_m2 < 1e-6
    values = {nv.name: nv.value for nv in f.outputs(ts[-1])}
    assert values == {NAME_ALPHA: f.alpha_ps, NAME_G: f.g_m2ps2}


def test_fit_is_deterministic_and_measured_mode_matches_carried_on_model_data() -> None:
    ts, pos, vel, var = _model_track(2.84, 0.35)
    p = np.tile(1.0 / var, (ts.size, 1))
    # at the truth, velocities measured equal to the particle's own give the
    # carried trajectory: both objectives vanish there and nowhere else
    al = np.array([0.5, 2.84, 6.0])
    g = np.array([0.02, 0.35, 4.0])
    carried = replay_cost(al, g, ts, pos, p, np.full((ts.size, 3), np.nan), pos[0], vel[0])
    measured = replay_cost(al, g, ts, pos, p, vel, pos[0], vel[0])
    for cost in (carried, measured):
        assert cost[1] < 1e-15 and cost[0] > 1.0 and cost[2] > 1.0
    results = []
    for _ in range(2):
        f = PotentialFilter(PotentialConfig(window_s=20.0, alpha0_ps=1.0, g0_m2ps2=1.0))
        for i in range(ts.size):
            f.add_fix(ts[i], pos[i], var, vel[i], force=True, refit=False)
        results.append(f.refit(force=True))
    # same seed, same data: the same answer, bit for bit
    assert results[0] == results[1]
    assert results[0] is not None
    # the default real-time budget (16 members, 20 generations, tol 1e-3) is
    # coarser than the full one above: about 7 % on G here; 10 % is claimed
    np.testing.assert_allclose(results[0], (2.84, 0.35), rtol=0.10)


def test_replay_cost_vectorised_equals_scalar() -> None:
    ts, pos, vel, var = _model_track(2.84, 0.35, n=20)
    p = np.tile(1.0 / var, (ts.size, 1))
    reset = np.full((ts.size, 3), np.nan)
    al = np.array([0.3, 2.84, 7.0])
    g = np.array([0.01, 0.35, 3.0])
    vec = replay_cost(al, g, ts, pos, p, reset, pos[0], vel[0])
    for k in range(3):
        one = replay_cost(al[k : k + 1], g[k : k + 1], ts, pos, p, reset, pos[0], vel[0])
        assert one[0] == pytest.approx(vec[k], rel=1e-12, abs=1e-20)
    assert vec[1] < 1e-15 < vec[0]


# --------------------------------------------------------------------------- kinematic flights


def _flight(
    seed: int, t_end: float = 40.0, rate_hz: float = 5.0, decel: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 3° descent at 60 m/s (optionally decelerating by 1 m/s² from t = 20 s) with noisy fixes."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, t_end, 1.0 / rate_hz)
    gamma = np.deg2rad(3.0)
    late = np.clip(t - 20.0, 0.0, None) if decel else np.zeros_like(t)
    v = 60.0 - late
    s = 60.0 * t - 0.5 * late**2
    pos = np.column_stack([s * np.cos(gamma), 0.1 * s, -500.0 + s * np.sin(gamma)])
    vel = np.column_stack([v * np.cos(gamma), 0.1 * v, v * np.sin(gamma)])
    sig = np.array([0.5, 0.5, 1.0])
    meas = pos + rng.normal(0.0, 1.0, pos.shape) * sig
    vmeas = vel + rng.normal(0.0, 0.1, vel.shape)
    return t, pos, meas, vmeas, sig**2


def test_fix_test_flags_10_sigma_and_passes_2_sigma() -> None:
    t, truth, meas, vmeas, var = _flight(5, t_end=20.0)
    f = PotentialFilter(PotentialConfig(seed=2))
    for k in range(t.size - 1):
        f.add_fix(t[k], meas[k], var, vmeas[k])
    tn = t[-1]
    sig = np.sqrt(var)
    probe = copy.deepcopy(f)
    bad = probe.test_fix(tn, truth[-1] + np.array([10.0 * sig[0], 0.0, 0.0]), var)
    assert bad.tested and not bad.consistent and bad.chi2 > bad.threshold
    bad_v = probe.test_fix(tn, truth[-1] + np.array([0.0, 0.0, 10.0 * sig[2]]), var)
    assert not bad_v.consistent
    for direction in np.eye(3):
        good = probe.test_fix(tn, truth[-1] + 2.0 * sig * direction, var)
        assert good.tested and good.consistent
    assert bad.threshold == pytest.approx(stats.chi2.ppf(1.0 - 1e-3, 3))
    # add_fix refuses the 10σ fix as a source and counts it
    res = f.add_fix(tn, truth[-1] + np.array([10.0 * sig[0], 0.0, 0.0]), var)
    assert not res.accepted and res.reason == "inconsistent"
    assert f.rejections["inconsistent"] == 1


def test_false_alarm_rate_and_gap_nees_are_consistent() -> None:
    # Normal fixes are rarely flagged, and predictions over 2-s gaps have a
    # normalised error close to its expectation (3) once calibrated.
    t, truth, meas, vmeas, var = _flight(8, t_end=90.0, decel=True)
    f = PotentialFilter(PotentialConfig(seed=4))
    nees: list[float] = []
    flagged = 0
    tested = 0
    for k in range(t.size):
        if k > 100 and k % 10 == 0 and k + 10 < t.size:
            pred = f.predict(t[k + 9])
            e = truth[k + 9] - pred.pos_ned_m
            nees.append(float(e @ np.linalg.solve(pred.cov_ned_m2, e)))
        res = f.add_fix(t[k], meas[k], var, vmeas[k])
        tested += res.tested
        flagged += res.tested and not res.consistent
    assert tested > 400
    assert flagged / tested < 0.02
    mean_nees = float(np.mean(nees))
    assert 1.0 < mean_nees < 6.0, mean_nees


def test_predicted_covariance_grows_with_horizon() -> None:
    t, _truth, meas, vmeas, var = _flight(1, t_end=30.0, decel=True)
    f = PotentialFilter(PotentialConfig(seed=1))
    for k in range(t.size):
        f.add_fix(t[k], meas[k], var, vmeas[k])
    tr = [np.trace(f.predict(t[-1] + h).cov_ned_m2) for h in (0.0, 0.5, 2.0, 5.0, 20.0)]
    assert all(b > a for a, b in zip(tr, tr[1:], strict=False))
    with pytest.raises(ValueError):
        f.predict(t[-1] - 1.0)


def test_gap_prediction_tracks_steady_flight() -> None:
    t, truth, meas, vmeas, var = _flight(2, t_end=30.0)
    f = PotentialFilter(PotentialConfig(seed=3))
    for k in range(t.size):
        f.add_fix(t[k], meas[k], var, vmeas[k])
    pred = f.predict(t[-1] + 2.0)
    truth_end = truth[-1] + (truth[-1] - truth[-2]) * 10.0  # 2 s at 5 Hz, constant velocity
    assert np.linalg.norm(pred.pos_ned_m - truth_end) < 3.0
    assert np.linalg.norm(pred.vel_ned_mps - (truth[-1] - truth[-2]) * 5.0) < 1.0


def test_bad_input_is_counted_not_raised() -> None:
    f = PotentialFilter()
    assert f.add_fix(0.0, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]).accepted
    assert f.add_fix(1.0, [np.nan, 0.0, 0.0], [1.0, 1.0, 1.0]).reason == "non_finite_position"
    assert f.add_fix(1.0, [0.0, 0.0, 0.0], [1.0, 0.0, 1.0]).reason == "bad_variance"
    assert f.add_fix(1.0, [0.0, 0.0], [1.0, 1.0, 1.0]).reason == "bad_shape"
    assert f.add_fix(0.0, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]).reason == "time_not_increasing"
    assert f.add_fix(2.0, [0, 0, 0], [1, 1, 1], [np.inf, 0, 0]).reason == "bad_velocity"
    assert f.rejections == {
        "non_finite_position": 1,
        "bad_variance": 1,
        "bad_shape": 1,
        "time_not_increasing": 1,
        "bad_velocity": 1,
    }
    assert f.n_sources == 1
    with pytest.raises(ValueError):
        PotentialFilter().predict(0.0)
    with pytest.raises(ValueError):
        f.test_fix(1.0, [np.nan, 0.0, 0.0], [1.0, 1.0, 1.0])


def test_restarts_after_persistent_inconsistency() -> None:
    t, _truth, meas, vmeas, var = _flight(6, t_end=20.0)
    cfg = PotentialConfig(seed=6, max_consecutive_inconsistent=3)
    f = PotentialFilter(cfg)
    k0 = 60
    for k in range(k0):
        f.add_fix(t[k], meas[k], var, vmeas[k])
    jump = np.array([400.0, 0.0, 0.0])  # e.g. the receiver re-acquired after a stale period
    reasons = [f.add_fix(t[k], meas[k] + jump, var, vmeas[k]) for k in range(k0, k0 + 6)]
    assert [r.accepted for r in reasons[:3]] == [False, False, False]
    assert reasons[3].accepted and f.rejections["restart"] == 1
    assert all(r.accepted for r in reasons[4:])
    pred = f.predict(t[k0 + 6])
    assert np.linalg.norm(pred.pos_ned_m - (meas[k0 + 6] + jump)) < 10.0


def test_config_is_validated() -> None:
    for bad in (
        {"window_s": 0.0},
        {"false_alarm_prob": 1.0},
        {"alpha_bounds_ps": (1.0, 0.5)},
        {"alpha0_ps": 50.0},
        {"velocity_mode": "other"},
        {"max_sources": 0},
        {"g_bounds_m2ps2": (0.0, 1.0)},
    ):
        with pytest.raises(ValueError):
            PotentialConfig(**bad)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- combination


def test_combine_predictions_is_the_information_weighted_mean() -> None:
    rng = np.random.default_rng(9)
    m = rng.normal(size=(3, 3))
    pa = m @ m.T + 0.5 * np.eye(3)
    m = rng.normal(size=(3, 3))
    pb = m @ m.T + 2.0 * np.eye(3)
    a = rng.normal(size=3)
    b = rng.normal(size=3)
    pos, cov = combine_predictions(a, pa, b, pb)
    info = np.linalg.inv(pa) + np.linalg.inv(pb)
    cov_ref = np.linalg.inv(info)
    pos_ref = cov_ref @ (np.linalg.solve(pa, a) + np.linalg.solve(pb, b))
    np.testing.assert_allclose(pos, pos_ref, atol=1e-12)
    np.testing.assert_allclose(cov, cov_ref, atol=1e-12)
    np.testing.assert_allclose(cov, cov.T)
    # a useless second prediction changes nothing; a perfect one takes over
    pos2, cov2 = combine_predictions(a, pa, b, 1e12 * np.eye(3))
    np.testing.assert_allclose(pos2, a, atol=1e-9)
    np.testing.assert_allclose(cov2, pa, atol=1e-9)
    pos3, cov3 = combine_predictions(a, pa, b, np.zeros((3, 3)))
    np.testing.assert_allclose(pos3, b, atol=1e-12)
    np.testing.assert_allclose(cov3, 0.0, atol=1e-12)
    with pytest.raises(ValueError):
        combine_predictions(a, pa, b[:2], pb[:2, :2])
    with pytest.raises(ValueError):
        combine_predictions(a, np.zeros((3, 3)), b, np.zeros((3, 3)))


def test_particle_without_velocity_starts_where_velocity_becomes_known() -> None:
    # positions only: the first fix gives no velocity, so the particle must not
    # be carried from it with a placeholder velocity (that would leave a lag)
    cfg = PotentialConfig(alpha0_ps=10.0, g0_m2ps2=1e-6, g_bounds_m2ps2=(1e-6, 1.0))
    f = PotentialFilter(cfg)
    vel = np.array([60.0, -5.0, 3.0])
    for k in range(3):
        t = 0.2 * k
        f.add_fix(t, vel * t, [0.25, 0.25, 1.0], refit=False)
    pred = f.predict(1.4)
    np.testing.assert_allclose(pred.pos_ned_m, vel * 1.4, atol=1e-3)
    np.testing.assert_allclose(pred.vel_ned_mps, vel, atol=1e-3)
