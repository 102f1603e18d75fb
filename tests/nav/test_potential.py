"""Tests of the position-potential filter (Grzegorzewski 2005): closed form, fit, fix test,
covariance."""

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
    # Grzegorzewski (2005): for large α only the newest fix matters and
    # k(t) = k_0n + W1(t) Δk_n + W2(t) k̇_n with A_k ≈ 2 p_kn, and p_kn = 1 with
    # the weights relative to the newest fix's (G·A independent of σ).
    rng = np.random.default_rng(3)
    n = 8
    t_src = np.arange(n) * 2.0  # the paper's 2-s steps
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
        w1, w2, _, _ = transition_axis(g * 2.0, alpha, t)
        w_form = pos_src[-1] + w1 * (particle - pos_src[-1]) + w2 * vel
        np.testing.assert_allclose(general, w_form, atol=1e-6)
    # with a single source the two are the same for any α
    a1, b1 = field_sums(t_src[-1:], pos_src[-1:], p_src[-1:], 0.3, t_src[-1])
    general, _ = propagate_state(particle, vel, a1, b1, g, 0.3, 1.7)
    w1, w2, _, _ = transition_axis(g * 2.0, 0.3, 1.7)
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


# The paper's stable-descent and descent-rate-change values and two stiffer fields.
# Known limit (not hidden): for α ≲ 1.5 1/s the global valley of the objective
# is narrower than the seeding grid and the population can settle in the broad
# basin at the α upper bound; those cases are not claimed here.
@pytest.mark.parametrize(("alpha", "g"), [(2.84, 0.35), (3.82, 0.54), (8.0, 2.0), (6.0, 20.0)])
def test_fit_recovers_model_alpha_and_g(alpha: float, g: float) -> None:
    ts, pos, vel, var = _model_track(alpha, g)
    # the paper's objective alone (the multi-step terms are not zero on model data:
    # a frozen-field prediction ignores the sources added along the way)
    cfg = PotentialConfig(
        window_s=20.0, velocity_mode="carried", alpha0_ps=1.0, g0_ps2=1.0,
        de_maxiter=60, de_popsize=15, de_tol=1e-8, seed=11, fit_horizons_s=(),
    )  # fmt: skip
    f = PotentialFilter(cfg)
    for i in range(ts.size):
        res = f.add_fix(ts[i], pos[i], var, vel[i] if i == 0 else None, force=True, refit=False)
        assert res.accepted
    # the objective is zero at the truth and the optimiser finds it
    out = f.refit(force=True)
    assert out is not None
    assert f.alpha_ps == pytest.approx(alpha, rel=1e-3)
    assert f.g_ps2 == pytest.approx(g, rel=1e-3)
    assert f.last_fit_cost_m2 is not None and f.last_fit_cost_m2 < 1e-6
    values = {nv.name: nv.value for nv in f.outputs(ts[-1])}
    assert values == {NAME_ALPHA: f.alpha_ps, NAME_G: f.g_ps2}


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
        cfg = PotentialConfig(
            window_s=20.0, alpha0_ps=1.0, g0_ps2=1.0, fit_horizons_s=(), velocity_weights=(1.0,)
        )
        f = PotentialFilter(cfg)
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


def _gap_nees(decel: bool, seed: int) -> tuple[list[float], int, int]:
    """Normalised errors of 1.8 s predictions (every 2 s after 20 s) on a 90 s descent,
    and how many fixes were tested and flagged meanwhile."""
    t, truth, meas, vmeas, var = _flight(seed, t_end=90.0, decel=decel)
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
    return nees, tested, flagged


def _nees_upper(n: int) -> float:
    """Upper 99.5 % bound of the mean of ``n`` chi-square(3) normalised errors."""
    return float(stats.chi2.ppf(0.995, 3 * n) / n)


def test_steady_descent_gap_covariance_is_not_optimistic() -> None:
    # Constant velocity: predictions over 2-s gaps must not err more than their
    # covariance says (mean NEES below the chi-square bound). The covariance is
    # deliberately conservative here (mean NEES about 2: the newest fix's whole
    # variance is added, see the module docstring), so only the upper side is tested.
    nees, tested, flagged = _gap_nees(decel=False, seed=8)
    assert tested > 400 and flagged / tested < 0.02
    assert float(np.mean(nees)) < _nees_upper(len(nees)), np.mean(nees)


def test_decelerating_descent_false_alarms_are_rare() -> None:
    nees, tested, flagged = _gap_nees(decel=True, seed=8)
    assert tested > 400
    assert flagged / tested < 0.02
    assert len(nees) > 30


@pytest.mark.xfail(
    strict=True,
    reason="known weakness: in a sustained 1 m/s^2 deceleration the 2-s covariance is "
    "optimistic (mean NEES 5.8 here; 3.3-6.6 over four seeds of a variant levelling off "
    "at 20 m/s); cause not established (the calibration's in-sample fit residuals are "
    "the suspect)",
)
def test_decelerating_descent_gap_covariance_is_not_optimistic() -> None:
    nees, _, _ = _gap_nees(decel=True, seed=8)
    assert float(np.mean(nees)) < _nees_upper(len(nees)), np.mean(nees)


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
    # the suspect model tests nothing until the restarted window is refitted,
    # which happens once it spans first_fit_span_s: no restart loop
    assert not f.calibrated
    fits = f.fit_count
    t_restart = t[k0 + 3]
    k = k0 + 6
    while f.fit_count == fits:
        res = f.add_fix(t[k], meas[k] + jump, var, vmeas[k])
        assert res.accepted and not res.tested
        k += 1
    assert t[k - 1] - t_restart <= cfg.first_fit_span_s + 1e-9
    assert f.calibrated
    for j in range(k, t.size):
        assert f.add_fix(t[j], meas[j] + jump, var, vmeas[j]).tested
    assert f.rejections["restart"] == 1


def test_config_is_validated() -> None:
    for bad in (
        {"window_s": 0.0},
        {"false_alarm_prob": 1.0},
        {"alpha_bounds_ps": (1.0, 0.5)},
        {"alpha0_ps": 50.0},
        {"velocity_mode": "other"},
        {"max_sources": 0},
        {"g_bounds_ps2": (0.0, 1.0)},
    ):
        with pytest.raises(ValueError, match=next(iter(bad))):
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


def test_combine_predictions_with_shared_error() -> None:
    # b is a's prediction plus independent noise: e_b = e_a + n, so P_ab = P_a
    # and b adds nothing -> K = 0; with P_ab = 0 the combination would (wrongly)
    # move towards b and shrink the covariance
    rng = np.random.default_rng(10)
    m = rng.normal(size=(3, 3))
    pa = m @ m.T + 0.5 * np.eye(3)
    pn = np.diag([0.3, 0.7, 1.1])
    a, b = rng.normal(size=3), rng.normal(size=3)
    pos, cov = combine_predictions(a, pa, b, pa + pn, pa)
    np.testing.assert_allclose(pos, a, atol=1e-12)
    np.testing.assert_allclose(cov, pa, atol=1e-12)
    # a Monte-Carlo check of the general case: the returned covariance is the
    # error covariance of the combination, and no other gain does better
    n = 200_000
    la = np.linalg.cholesky(pa)
    ea = rng.normal(size=(n, 3)) @ la.T
    mix = np.diag([0.8, -0.3, 0.5])
    eb = ea @ mix.T + rng.normal(size=(n, 3)) @ np.linalg.cholesky(pn).T
    pab = pa @ mix.T
    pb = mix @ pa @ mix.T + pn
    zero = np.zeros(3)
    x, p = combine_predictions(zero, pa, zero, pb, pab)
    np.testing.assert_allclose(x, 0.0, atol=1e-12)
    k = (pa - pab) @ np.linalg.inv(pa + pb - pab - pab.T)
    e = ea + (eb - ea) @ k.T
    np.testing.assert_allclose(np.cov(e.T), p, rtol=0.03, atol=0.01)
    # ignoring P_ab claims a smaller covariance than it achieves
    _x, p_indep = combine_predictions(zero, pa, zero, pb)
    k_indep = pa @ np.linalg.inv(pa + pb)
    e_indep = ea + (eb - ea) @ k_indep.T
    assert np.trace(np.cov(e.T)) < np.trace(np.cov(e_indep.T))
    assert np.trace(p_indep) < np.trace(np.cov(e_indep.T))


def test_particle_without_velocity_starts_where_velocity_becomes_known() -> None:
    # positions only: the first fix gives no velocity, so the particle must not
    # be carried from it with a placeholder velocity (that would leave a lag)
    cfg = PotentialConfig(alpha0_ps=10.0, g0_ps2=1e-6, g_bounds_ps2=(1e-6, 1.0))
    f = PotentialFilter(cfg)
    vel = np.array([60.0, -5.0, 3.0])
    for k in range(3):
        t = 0.2 * k
        f.add_fix(t, vel * t, [0.25, 0.25, 1.0], refit=False)
    pred = f.predict(1.4)
    np.testing.assert_allclose(pred.pos_ned_m, vel * 1.4, atol=1e-3)
    np.testing.assert_allclose(pred.vel_ned_mps, vel, atol=1e-3)


# --------------------------------------------------------------------------- fast paths, replay


def test_filter_fast_prediction_equals_general_closed_form() -> None:
    # the filter's per-anchor form (precomputed Bessel constants at s0) against
    # propagate_state over the branches: scipy range, small-argument series
    # (long horizons, tiny G·A), large s0 (falls back), mixed axes
    from companion.nav.potential.anchor import anchor_propagate, make_anchor

    rng = np.random.default_rng(21)
    pos = np.array([120.0, -40.0, -300.0])
    vel = np.array([60.0, 5.0, 3.0])
    for alpha in (1e-3, 0.5, 2.84, 10.0):
        for g in (1e-9, 1e-3, 0.35, 50.0):
            a = np.array([4.0, 4.0, 1.0]) * 10.0 ** rng.uniform(0.0, 3.0)
            b = a * (pos - rng.normal(0.0, 20.0, 3))
            anc = make_anchor(0.0, pos, vel, alpha, g, a, b)
            for h in (0.0, 0.013, 0.1, 1.0, 5.0, 20.0, 300.0):
                p_fast, v_fast = anchor_propagate(anc, h)
                p_ref, v_ref = propagate_state(pos, vel, a, b, g, alpha, h)
                scale = 1.0 + np.abs(p_ref - pos).max()
                np.testing.assert_allclose(p_fast, p_ref, rtol=0, atol=1e-9 * scale)
                np.testing.assert_allclose(
                    v_fast, v_ref, rtol=0, atol=1e-9 * (1 + abs(v_ref).max())
                )


def test_replay_functions_share_one_replay() -> None:
    from companion.nav.potential import fit_pairs, replay_anchors, replay_state

    ts, pos, vel, var = _model_track(2.84, 0.35, n=30)
    rng = np.random.default_rng(4)
    meas = pos + rng.normal(0.0, 0.5, pos.shape)
    p = np.tile(1.0 / var, (ts.size, 1))
    reset = vel + rng.normal(0.0, 0.1, vel.shape)
    reset[:, 2] = np.nan
    al, g = 3.3, 0.2
    apos, avel, aa, bb = replay_anchors(al, g, ts, meas, p, reset, meas[0], vel[0])
    sp, sv = replay_state(al, g, ts, meas, p, reset, meas[0], vel[0])
    np.testing.assert_array_equal(sp, apos[-1])
    np.testing.assert_array_equal(sv, avel[-1])
    # the field sums are the paper's sums at each fix; each carried position is the
    # frozen-field prediction from the previous fix
    for i in (0, 7, ts.size - 1):
        a_ref, b_ref = field_sums(ts[: i + 1], meas[: i + 1], p[: i + 1], al, ts[i])
        np.testing.assert_allclose(aa[i], a_ref, rtol=1e-12)
        np.testing.assert_allclose(bb[i], b_ref, rtol=1e-12)
    one_step = sum(
        float(np.sum((propagate_state(apos[i - 1], avel[i - 1], aa[i - 1], bb[i - 1], g, al,
                                      ts[i] - ts[i - 1])[0] - meas[i]) ** 2))
        for i in range(1, ts.size)
    )  # fmt: skip
    c0 = replay_cost(np.array([al]), np.array([g]), ts, meas, p, reset, meas[0], vel[0])
    assert c0[0] == pytest.approx(one_step, rel=1e-9)
    jj, kk = fit_pairs(ts, (0.5, 2.0), 1.0)
    assert jj.size > 0 and np.all(kk > jj) and np.all(ts[kk] - ts[jj] >= 0.5 - 1e-9)
    multi = sum(
        float(np.sum((propagate_state(apos[j], avel[j], aa[j], bb[j], g, al, ts[k] - ts[j])[0]
                      - meas[k]) ** 2))
        for j, k in zip(jj, kk, strict=True)
    )  # fmt: skip
    c1 = replay_cost(np.array([al]), np.array([g]), ts, meas, p, reset, meas[0], vel[0], (jj, kk))
    assert c1[0] == pytest.approx(one_step + multi, rel=1e-9)


def test_fit_pairs_starts_and_horizons() -> None:
    from companion.nav.potential import fit_pairs

    t = np.arange(0.0, 3.01, 0.25)  # 13 fixes
    jj, kk = fit_pairs(t, (0.5, 1.0), 1.0)
    # starts at 0, 1, 2 s; ends 0.5 and 1 s later, beyond the last fix dropped
    assert list(zip(t[jj], t[kk], strict=True)) == [
        (0.0, 0.5), (0.0, 1.0), (1.0, 1.5), (1.0, 2.0), (2.0, 2.5), (2.0, 3.0),
    ]  # fmt: skip
    assert fit_pairs(t, (), 1.0)[0].size == 0


def test_reset_velocity_blends_and_fills() -> None:
    from companion.nav.potential import reset_velocity

    vm = np.array([10.0, np.nan, 2.0, np.nan])
    vd = np.array([12.0, 3.0, np.nan, np.nan])
    out = reset_velocity(vm, vd, 0.25)
    np.testing.assert_allclose(out[:3], [11.5, 3.0, 2.0])
    assert np.isnan(out[3])


# --------------------------------------------------------------------------- velocity weight


def _straight(
    seed: int, pos_sigma: float, vel_sigma: float, t_end: float = 30.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, t_end, 0.1)
    v = np.array([55.0, 12.0, 2.9])
    truth = t[:, None] * v
    meas = truth + rng.normal(0.0, pos_sigma, truth.shape)
    vm = v + rng.normal(0.0, vel_sigma, truth.shape)
    vm[:, 2] = np.nan  # GPS_RAW_INT: no vertical velocity
    return t, truth, meas, vm, np.full(3, pos_sigma**2)


@pytest.mark.parametrize(
    ("pos_sigma", "vel_sigma", "expect_measured"), [(0.02, 0.3, False), (1.0, 0.02, True)]
)
def test_velocity_weight_follows_the_better_source(
    pos_sigma: float, vel_sigma: float, expect_measured: bool
) -> None:
    # precise positions and a noisy velocity: the position slope wins; noisy
    # positions and a precise velocity: the receiver's velocity wins
    t, _truth, meas, vm, var = _straight(5, pos_sigma, vel_sigma)
    f = PotentialFilter(PotentialConfig(seed=5))
    for k in range(t.size):
        f.add_fix(t[k], meas[k], var, vm[k])
    assert f.fit_count >= 2
    if expect_measured:
        assert f.velocity_weight >= 0.75
    else:
        assert f.velocity_weight <= 0.25


def test_gap_covariance_covers_correlated_fix_errors() -> None:
    # RTK-like fixes: small, slowly varying (Gauss-Markov, 60 s) errors that the
    # window's residuals against the fixes cannot see; the predicted
    # covariance must still cover the error against the truth (NEES ~ 3)
    rng = np.random.default_rng(12)
    dt, tau = 0.1, 60.0
    t = np.arange(0.0, 120.0, dt)
    sig = np.array([0.015, 0.015, 0.03])
    phi = np.exp(-dt / tau)
    err = np.empty((t.size, 3))
    err[0] = rng.normal(0.0, 1.0, 3) * sig
    for k in range(1, t.size):
        err[k] = phi * err[k - 1] + np.sqrt(1 - phi**2) * sig * rng.normal(0.0, 1.0, 3)
    v = np.array([33.0, 0.5, 1.7])
    truth = t[:, None] * v
    vm = v + rng.normal(0.0, 0.05, truth.shape)
    vm[:, 2] = np.nan
    f = PotentialFilter(PotentialConfig(seed=12))
    nees: list[float] = []
    for k in range(t.size):
        if k > 300 and k % 25 == 0 and k + 50 < t.size:
            for j in (10, 50):  # 1 s and 5 s ahead
                pred = f.predict(t[k - 1] + j * dt)
                e = truth[k - 1 + j] - pred.pos_ned_m
                nees.append(float(e @ np.linalg.solve(pred.cov_ned_m2, e)))
        f.add_fix(t[k], truth[k] + err[k], sig**2, vm[k])
    assert len(nees) > 40
    n = len(nees)
    lo, hi = stats.chi2.ppf([0.005, 0.995], 3 * n) / n  # two-sided 99 % for the mean
    assert lo < float(np.mean(nees)) < hi, np.mean(nees)


# ------------------------------------------------------------- accuracy class, real flights


def test_field_strength_does_not_depend_on_the_fixes_accuracy_class() -> None:
    # weights relative to the newest fix's: the same fixes reported at 1.5 cm
    # (RTK) or 1.5 m give the same field, the same fit and the same particle
    rng = np.random.default_rng(31)
    t = np.arange(0.0, 12.0, 0.1)
    v = np.array([38.0, 9.0, -1.5])
    truth = t[:, None] * v + 0.5 * np.array([0.0, 1.2, 0.0]) * t[:, None] ** 2
    meas = truth + rng.normal(0.0, 0.02, truth.shape)
    vm = v + np.array([0.0, 1.2, 0.0]) * t[:, None] + rng.normal(0.0, 0.05, truth.shape)
    sig = np.array([0.015, 0.015, 0.03])
    a_small, b_small = field_sums(t, meas, np.tile(1.0 / sig**2, (t.size, 1)), 2.84, t[-1])
    a_big, b_big = field_sums(t, meas, np.tile(1e-4 / sig**2, (t.size, 1)), 2.84, t[-1])
    np.testing.assert_allclose(a_small, a_big, rtol=1e-12)
    np.testing.assert_allclose(b_small, b_big, rtol=1e-12)
    # uniform accuracy: A = 2 Σ e^{α(t_i − t_n)} on every axis, whatever σ is
    np.testing.assert_allclose(a_small, 2.0 * np.exp(2.84 * (t - t[-1])).sum(), rtol=1e-12)
    cfg = PotentialConfig(
        seed=3, position_update=False, velocity_weights=(1.0,), velocity_fit_orders=(1,)
    )
    filters = [PotentialFilter(cfg), PotentialFilter(cfg)]
    for f, scale in zip(filters, (1.0, 100.0), strict=True):
        for k in range(t.size):
            f.add_fix(t[k], meas[k], (scale * sig) ** 2, vm[k], force=True)
    assert filters[0].fit_count >= 2
    assert filters[0].alpha_ps == pytest.approx(filters[1].alpha_ps, rel=1e-9)
    assert filters[0].g_ps2 == pytest.approx(filters[1].g_ps2, rel=1e-9)
    for h in (0.1, 2.0, 10.0):
        np.testing.assert_allclose(
            filters[0].predict(t[-1] + h).pos_ned_m,
            filters[1].predict(t[-1] + h).pos_ned_m,
            rtol=0,
            atol=1e-8,
        )


def _sim_one_step(scenario: str, seed: int) -> dict[str, np.ndarray | int | float]:
    """The engine's use on a simulated flight: receiver 0's fixes as measurements, the
    prediction at each new fix's time compared with it, then the fix added."""
    from companion.nav.gnss import gnss_measurement
    from companion.sim import make_scenario, simulate
    from companion.types import GnssFix

    fl = simulate(make_scenario(scenario), seed)
    f = PotentialFilter(PotentialConfig())
    chi2_s: list[float] = []  # against the filter's innovation covariance (its fix test)
    chi2_pr: list[float] = []  # against P + R (the prediction's covariance vs truth + fix's)
    horizon: list[float] = []
    t_fix: list[float] = []
    t_fits: list[float] = []
    t_restarts: list[float] = []
    for s in fl.samples:
        if not (isinstance(s, GnssFix) and s.receiver_id == 0):
            continue
        m = gnss_measurement(s, fl.frame)
        if f.calibrated and f.t_last_s is not None and m.t_s > f.t_last_s:
            pr = f.predict(m.t_s)
            d = m.pos_ned_m - pr.pos_ned_m
            # fixes as accurate as the newest throughout these flights: the
            # published innovation covariance is the fix test's S
            assert np.all(m.pos_var_ned_m2 == pr.anchor_var_ned_m2)
            c2 = float(d @ np.linalg.solve(pr.innov_cov_ned_m2, d))
            probe = f.test_fix(m.t_s, m.pos_ned_m, m.pos_var_ned_m2)
            if probe.tested:  # not while the window is short (after a GNSS loss)
                assert probe.chi2 == pytest.approx(c2, rel=1e-9)
            chi2_s.append(c2)
            horizon.append(pr.horizon_s)
            s_pr = pr.cov_ned_m2 + np.diag(m.pos_var_ned_m2)
            chi2_pr.append(float(d @ np.linalg.solve(s_pr, d)))
        n_fit, n_restart = f.fit_count, f.rejections.get("restart", 0)
        f.add_fix(m.t_s, m.pos_ned_m, m.pos_var_ned_m2, m.vel_ned_mps)
        t_fix.append(m.t_s)
        if f.fit_count > n_fit:
            t_fits.append(m.t_s)
        if f.rejections.get("restart", 0) > n_restart:
            t_restarts.append(m.t_s)
    return {
        "chi2": np.array(chi2_s),
        "chi2_pr": np.array(chi2_pr),
        "horizon": np.array(horizon),
        "t_fix": np.array(t_fix),
        "t_fits": np.array(t_fits),
        "t_restarts": np.array(t_restarts),
    }


def _fit_gaps_in_fix_time(t_fix: np.ndarray, t_fits: np.ndarray) -> np.ndarray:
    """Fix time between consecutive fits, not counting spans without fixes (GNSS loss)."""
    dt = np.diff(t_fix)
    step = float(np.median(dt))
    fix_time = np.concatenate([[0.0], np.cumsum(np.minimum(dt, 2.0 * step))])
    return np.diff(np.interp(t_fits, t_fix, fix_time))


@pytest.mark.parametrize(
    ("scenario", "max_restarts"),
    [
        # RTK fixed (1.5 cm, errors correlated over 30 s), MEMS IMU: parked,
        # taxi with turns, take-off, 40 m/s cruise with turns, approach (931 s).
        # A restart is the filter's answer to a manoeuvre its coasting particle
        # did not foresee (a turn's onset, the take-off roll): at most one per
        # onset, never a loop.
        ("nominal", 15),
        # DGPS (0.5 m / 1.0 m, correlated over 120 s), 60 s with no GNSS at all
        ("cruise_gnss_loss", 3),
    ],
)
def test_one_step_consistency_on_simulated_flights(scenario: str, max_restarts: int) -> None:
    r = _sim_one_step(scenario, 1)
    chi2, horizon = r["chi2"], r["horizon"]
    assert isinstance(chi2, np.ndarray) and isinstance(horizon, np.ndarray)
    # every prediction over less than a second: one fix interval, or up to
    # four while a run of fixes is rejected; not those from before the 60-s
    # loss to the first fixes after it (a kilometre off after a minute of
    # turning without an IMU: rejected, then a restart on the new fixes)
    one_step = horizon < 1.0
    cfg = PotentialConfig()
    assert np.count_nonzero(~one_step) <= cfg.max_consecutive_inconsistent + 1
    chi2 = chi2[one_step]
    assert chi2.size > 2000
    q = stats.chi2.isf(1e-3, 3)
    # the fix test's statistic is χ²(3)-like: few false alarms, mean near 3
    assert np.mean(chi2 > q) <= 0.01
    assert 2.0 <= float(np.mean(chi2)) <= 4.5
    # P + R (the prediction's error against the truth plus the fix's) is
    # conservative for this test: the fixes' slowly varying errors are shared
    # by the prediction; no more exceedances than the innovation test
    chi2_pr = r["chi2_pr"]
    assert isinstance(chi2_pr, np.ndarray)
    assert np.mean(chi2_pr[one_step] > q) <= 0.01
    # no restart loop: few restarts, separated by fits
    t_restarts, t_fits, t_fix = r["t_restarts"], r["t_fits"], r["t_fix"]
    assert isinstance(t_restarts, np.ndarray) and isinstance(t_fits, np.ndarray)
    assert isinstance(t_fix, np.ndarray)
    assert t_restarts.size <= max_restarts
    for tr in t_restarts:
        assert np.any((t_fits > tr) & (t_fits <= tr + 3.0)), f"no fit after the restart at {tr}"
    # fits keep happening at refit_interval_s (a restart's await adds first_fit_span_s)
    assert t_fits.size > 0 and t_fits[0] < t_fix[0] + cfg.refit_interval_s
    gaps = _fit_gaps_in_fix_time(t_fix, t_fits)
    assert gaps.max() <= cfg.refit_interval_s + cfg.first_fit_span_s + 0.5
    assert t_fix[-1] - t_fits[-1] <= cfg.refit_interval_s + 0.5


def test_speed_change_triggers_a_refit() -> None:
    # parked 12 s, then a take-off roll at 2 m/s²: α and G fitted on the parked
    # window are refitted once the speed leaves its band, not refit_interval_s later
    rng = np.random.default_rng(41)
    cfg = PotentialConfig(seed=41, refit_interval_s=5.0)
    f = PotentialFilter(cfg)
    t = np.arange(0.0, 20.0, 0.1)
    roll = np.clip(t - 12.0, 0.0, None)
    truth = np.column_stack([roll**2, np.zeros_like(t), np.zeros_like(t)])
    vel = np.column_stack([2.0 * roll, np.zeros_like(t), np.full_like(t, np.nan)])
    sig = np.array([0.015, 0.015, 0.03])
    fit_t: list[float] = []
    for k in range(t.size):
        n = f.fit_count
        f.add_fix(t[k], truth[k] + rng.normal(0.0, 1.0, 3) * sig * 0.1, sig**2, vel[k])
        if f.fit_count > n:
            fit_t.append(float(t[k]))
    before = [x for x in fit_t if x <= 12.0]
    after = np.array([x for x in fit_t if x > 12.0])
    # parked: the periodic fits only
    assert np.all(np.diff(before) >= cfg.refit_interval_s - 1e-9)
    # rolling: refitted each time the speed leaves its band (1 m/s + 20 %),
    # well before refit_interval_s, and never closer than refit_min_interval_s
    assert after.size >= 4
    gaps = np.diff(after)
    assert np.all(gaps < cfg.refit_interval_s - 1.0)
    assert np.all(gaps >= cfg.refit_min_interval_s - 1e-9)
