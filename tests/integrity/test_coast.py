"""The inertial coasting reference: closed forms, slot logic, frames, and consistency vs truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from companion.integrity.coast import CoastConfig, CoastState, InertialCoast
from companion.nav.navigator import NavState
from companion.nav.rotations import euler_to_mat_nb
from companion.types import AttitudeSample, GnssFix, ImuSample

G = np.array([0.0, 0.0, 9.81])


def att(t: float, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> AttitudeSample:
    return AttitudeSample(t, t, roll, pitch, yaw, np.zeros(3))


def imu(t: float, f_b: np.ndarray) -> ImuSample:
    return ImuSample(t, t, np.asarray(f_b, dtype=float), np.zeros(3))


def state(
    t: float, pos: np.ndarray, vel: np.ndarray, sp: float = 0.02, sv: float = 0.01
) -> NavState:
    return NavState(t, np.asarray(pos, float), np.asarray(vel, float), np.eye(3) * sp**2,
                    np.eye(3) * sv**2)  # fmt: skip


def fly_constant(
    coast: InertialCoast, acc_ned: np.ndarray, euler: tuple[float, float, float], t0: float,
    t1: float, rate: float = 100.0,
) -> None:  # fmt: skip
    """Feed a constant NED acceleration seen by an IMU at a fixed attitude (no height change)."""
    c = euler_to_mat_nb(*euler)
    f_b = c.T @ (acc_ned - G)
    coast.on_attitude(att(t0, *euler))
    for k in range(int(round((t1 - t0) * rate)) + 1):
        coast.on_imu(imu(t0 + k / rate, f_b))


# ----------------------------------------------------------------------------- config


@pytest.mark.parametrize(
    "kwargs",
    [{"slots": 0}, {"slots": 2.5}, {"life_s": 0.0}, {"history_s": math.nan},
     {"acc_vrw_mps_rts": -1.0}, {"att_err_sigma_rad": (0.1, 0.1)}],
)  # fmt: skip
def test_config_validation(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        CoastConfig(**kwargs)  # type: ignore[arg-type]


def test_grade_figures_are_the_simulators() -> None:
    from companion.nav.grades import ATTITUDE_ERROR_BY_GRADE, IMU_GRADES

    for grade in ("tactical", "mems"):
        cfg = CoastConfig.for_grade(grade)
        g = IMU_GRADES[grade]
        assert cfg.acc_bias_sigma_mps2 == pytest.approx(
            math.hypot(g.acc_bias_sigma_mps2, g.acc_instability_mps2)
        )
        assert cfg.acc_vrw_mps_rts == g.acc_noise_density_mps2_rthz
        assert cfg.att_err_sigma_rad == ATTITUDE_ERROR_BY_GRADE[grade][0]
    assert CoastConfig() == CoastConfig.for_grade("tactical")
    with pytest.raises(ValueError):
        CoastConfig.for_grade("consumer")


# ----------------------------------------------------------------------------- closed forms


def test_constant_acceleration_matches_the_closed_form_at_an_older_time() -> None:
    coast = InertialCoast(CoastConfig(slots=1, life_s=100.0), G)
    acc = np.array([0.5, -0.2, 0.0])
    euler = (0.1, -0.05, 0.7)
    fly_constant(coast, acc, euler, 0.0, 1.0)
    p0, v0 = np.array([10.0, -5.0, 0.0]), np.array([60.0, 5.0, 0.0])
    assert coast.anchor_due(1.0)
    coast.anchor(state(1.0, p0, v0))
    assert not coast.anchor_due(1.0)
    fly_constant(coast, acc, euler, 1.01, 31.0)
    t = 30.537  # a fix time between IMU samples, older than the newest
    tau = t - 1.0
    (name, ref), = coast.references(t).items()  # fmt: skip
    assert name == "ins0" and isinstance(ref, CoastState) and ref.anchor_t_s == 1.0
    np.testing.assert_allclose(ref.pos_ned_m, p0 + v0 * tau + 0.5 * acc * tau**2, atol=1e-6)
    np.testing.assert_allclose(ref.vel_ned_mps, v0 + acc * tau, atol=1e-9)
    # beyond the newest sample: extrapolated with the last acceleration
    ref2 = coast.references(31.3)["ins0"]
    tau2 = 30.3
    np.testing.assert_allclose(ref2.pos_ned_m, p0 + v0 * tau2 + 0.5 * acc * tau2**2, atol=1e-6)
    assert coast.references(40.0) == {}  # too far beyond the history
    assert coast.references(20.0) == {}  # older than the history
    assert coast.stats["reference_outside_history"] == 2


def test_gravity_follows_height_with_the_free_air_gradient() -> None:
    """Hovering 300 m above the frame origin (which is 100 m above the ellipsoid): the
    accelerometer reads the normal gravity there; the prediction must stay put."""
    from companion.nav import earth

    lat = math.radians(52.0)
    g0 = earth.gravity_ned_mps2(lat, 100.0)
    coast = InertialCoast(CoastConfig(slots=1, life_s=100.0), g0)
    f_b = -earth.gravity_ned_mps2(lat, 400.0)
    coast.on_attitude(att(0.0))
    for k in range(101):
        coast.on_imu(imu(k / 100.0, f_b))
    p0 = np.array([0.0, 0.0, -300.0])
    coast.anchor(state(1.0, p0, np.zeros(3)))
    for k in range(101, 6101):
        coast.on_imu(imu(k / 100.0, f_b))
    ref = coast.references(61.0)["ins0"]
    # without the gradient the error would be 0.5 * 9.3e-4 * 60^2 = 1.7 m
    np.testing.assert_allclose(ref.pos_ned_m, p0, atol=0.01)


def test_covariance_grows_as_the_error_model() -> None:
    cfg = CoastConfig(slots=1, life_s=100.0)
    coast = InertialCoast(cfg, G)
    fly_constant(coast, np.zeros(3), (0.0, 0.0, 0.0), 0.0, 1.0)
    coast.anchor(state(1.0, np.zeros(3), np.zeros(3), sp=0.02, sv=0.01))
    fly_constant(coast, np.zeros(3), (0.0, 0.0, 0.0), 1.01, 21.0)
    ref = coast.references(21.0)["ins0"]
    tau = 20.0
    sb2, q = cfg.acc_bias_sigma_mps2**2, cfg.acc_vrw_mps_rts**2
    tilt = np.array(cfg.att_err_sigma_rad) * 9.81  # level: [f x] psi = g (psi_E, -psi_N, 0)
    s_a = sb2 + np.array([tilt[1] ** 2, tilt[0] ** 2, 0.0])
    np.testing.assert_allclose(np.diag(ref.acc_cov_ned_m2ps4), s_a, rtol=1e-6)
    want_p = 0.02**2 + tau**2 * 0.01**2 + tau**4 / 4 * s_a + q * tau**3 / 3
    want_v = 0.01**2 + tau**2 * s_a + q * tau
    np.testing.assert_allclose(np.diag(ref.pos_cov_ned_m2), want_p, rtol=1e-6)
    np.testing.assert_allclose(np.diag(ref.vel_cov_ned_m2ps2), want_v, rtol=1e-6)


def test_bias_estimate_is_removed_from_the_specific_force() -> None:
    coast = InertialCoast(CoastConfig(slots=1, life_s=100.0), G)
    bias = np.array([0.01, -0.02, 0.03])
    c = euler_to_mat_nb(0.0, 0.0, 0.0)
    f_b = c.T @ (np.zeros(3) - G) + bias
    coast.on_attitude(att(0.0))
    for k in range(101):
        coast.on_imu(imu(k / 100.0, f_b))
    coast.anchor(state(1.0, np.zeros(3), np.zeros(3)), bias, np.eye(3) * 1e-8)
    for k in range(101, 1101):
        coast.on_imu(imu(k / 100.0, f_b))
    ref = coast.references(11.0)["ins0"]
    np.testing.assert_allclose(ref.pos_ned_m, 0.0, atol=1e-6)
    assert ref.acc_cov_ned_m2ps4 is not None and ref.acc_cov_ned_m2ps4[2, 2] == pytest.approx(1e-8)


# ----------------------------------------------------------------------------- slots


def test_slots_are_staggered_and_reanchored_after_their_life() -> None:
    cfg = CoastConfig(slots=3, life_s=30.0)
    coast = InertialCoast(cfg, G)
    assert not coast.anchor_due(0.0)  # no IMU yet
    coast.on_attitude(att(0.0))
    anchors: list[tuple[float, list[float | None]]] = []
    f_b = -G
    for k in range(0, 9001):  # 90 s at 100 Hz
        t = k / 100.0
        coast.on_imu(imu(t, f_b))
        if coast.anchor_due(t):
            coast.anchor(state(t, np.zeros(3), np.zeros(3)))
            anchors.append((t, coast.slot_ages_s(t)))
        if t >= 20.0:  # three slots staggered over 30 s: one is always >= 20 s old
            assert max(a for a in coast.slot_ages_s(t) if a is not None) >= 20.0 - 1e-9
    times = [a[0] for a in anchors]
    # first anchors at 0, 10, 20 s; then each slot again after 30 s
    np.testing.assert_allclose(times, [0, 10, 20, 30, 40, 50, 60, 70, 80, 90], atol=0.011)
    ages = coast.slot_ages_s(95.0)
    assert sorted(a for a in ages if a is not None) == pytest.approx([5.0, 15.0, 25.0])
    assert coast.stats["anchors"] == 10
    coast.anchor(state(90.0, np.zeros(3), np.zeros(3)))
    assert coast.stats["anchor_not_due"] == 1


def test_slots_overdue_together_are_restaggered() -> None:
    """Anchoring suspended for a minute (an outage, a fault): when it resumes, with the
    engine asking at every 0.1 s publication tick, the overdue slots are re-anchored a
    stagger apart (so they keep expiring one at a time), not all at the next ticks."""
    cfg = CoastConfig(slots=3, life_s=30.0)
    coast = InertialCoast(cfg, G)
    coast.on_attitude(att(0.0))
    anchors: list[float] = []
    for k in range(0, 15001):  # 150 s at 100 Hz
        t = k / 100.0
        coast.on_imu(imu(t, -G))
        suspended = 35.0 <= t < 95.0
        if k % 10 == 0 and not suspended and coast.anchor_due(t):
            coast.anchor(state(t, np.zeros(3), np.zeros(3)))
            anchors.append(t)
    resumed = [t for t in anchors if t >= 95.0]
    assert resumed[:3] == pytest.approx([95.0, 104.5, 114.0], abs=0.11)
    assert min(np.diff(resumed)) >= 0.95 * cfg.life_s / cfg.slots - 1e-9
    ages = sorted(a for a in coast.slot_ages_s(149.0) if a is not None)
    assert ages[1] - ages[0] > 9.0 and ages[2] - ages[1] > 9.0


def test_imu_gap_and_bad_inputs() -> None:
    coast = InertialCoast(CoastConfig(slots=1), G)
    coast.on_imu(imu(0.0, -G))
    assert coast.stats["imu_before_attitude"] == 1
    coast.on_attitude(AttitudeSample(0.0, 0.0, math.nan, 0.0, 0.0, np.zeros(3)))
    assert coast.stats["bad_attitude"] == 1
    fly_constant(coast, np.zeros(3), (0.0, 0.0, 0.0), 0.0, 1.0)
    coast.anchor(state(1.0, np.zeros(3), np.zeros(3)))
    coast.on_imu(imu(1.0, -G))
    assert coast.stats["imu_time_not_increasing"] == 1
    coast.on_imu(imu(1.01, np.array([math.nan, 0.0, 0.0])))
    assert coast.stats["bad_imu"] == 1
    bad = NavState(1.0, np.full(3, math.nan), np.zeros(3), np.eye(3), np.eye(3))
    coast.anchor(bad)
    assert coast.stats["bad_anchor"] == 1
    assert coast.references(1.0) == {} or "ins0" in coast.references(1.0)
    fly_constant(coast, np.zeros(3), (0.0, 0.0, 0.0), 2.0, 3.0)  # a 1 s gap
    assert coast.stats["imu_gap"] == 1 and coast.stats["slots_dropped_imu_gap"] == 1
    assert coast.references(3.0) == {}
    assert coast.anchor_due(3.0)
    with pytest.raises(ValueError):
        InertialCoast(CoastConfig(), np.zeros(2))


def test_shift_frame_re_expresses_the_predictions() -> None:
    acc = np.array([0.3, 0.1, 0.0])
    euler = (0.05, 0.02, 1.0)
    rot = euler_to_mat_nb(0.0, 0.0, 0.01)  # a small rotation, as between two local frames
    off = np.array([-500.0, 200.0, 3.0])
    coasts = [InertialCoast(CoastConfig(slots=1, life_s=100.0), G) for _ in range(2)]
    for c in coasts:
        fly_constant(c, acc, euler, 0.0, 1.0)
        c.anchor(state(1.0, np.array([1.0, 2.0, -100.0]), np.array([50.0, 0.0, 0.0])))
        fly_constant(c, acc, euler, 1.01, 10.0)
    coasts[1].shift_frame(rot, off)
    a, b = coasts[0].references(9.95)["ins0"], coasts[1].references(9.95)["ins0"]
    np.testing.assert_allclose(b.pos_ned_m, rot @ a.pos_ned_m + off, atol=1e-9)
    np.testing.assert_allclose(b.vel_ned_mps, rot @ a.vel_ned_mps, atol=1e-9)
    np.testing.assert_allclose(b.pos_cov_ned_m2, rot @ a.pos_cov_ned_m2 @ rot.T, atol=1e-12)
    with pytest.raises(ValueError):
        coasts[1].shift_frame(np.eye(2), off)
    coasts[1].reset()
    assert coasts[1].references(9.95) == {}


# ----------------------------------------------------------------------------- vs truth

sim = pytest.importorskip("companion.sim")

AGES_S = (5.0, 10.0, 20.0, 40.0, 60.0)
SEEDS = (1, 2, 3, 4, 5)
ANCHOR_SIGMA = (0.02, 0.01)
"""Anchor position / velocity 1-sigma (m, m/s): an RTK-aided navigator's."""


def nees_vs_truth(grade: str, seed: int) -> dict[float, list[float]]:
    """NEES of each slot's position prediction at the given ages, anchors from truth + noise
    drawn from the anchor covariance, on a simulated approach with the grade's IMU."""
    sc = sim.make_scenario("approach", imu_grade=grade, duration_s=150.0)
    flight = sim.simulate(sc, seed=seed)
    fr = flight.frame
    from companion.nav import earth

    coast = InertialCoast(
        CoastConfig.for_grade(grade, slots=4, life_s=61.0),
        earth.gravity_ned_mps2(fr.lat0_rad, fr.alt0_m),
    )
    rng = np.random.default_rng(seed + 1000)
    sp, sv = ANCHOR_SIGMA
    due: list[tuple[float, float, str]] = []  # (eval time, age, slot)
    out: dict[float, list[float]] = {a: [] for a in AGES_S}
    for s in flight.samples:
        if isinstance(s, AttitudeSample):
            coast.on_attitude(s)
        elif isinstance(s, ImuSample):
            coast.on_imu(s)
            if coast.anchor_due(s.t_s) and s.t_s < flight.truth.t_s[-1] - 61.0:
                tr = flight.truth.at(s.t_s)
                coast.anchor(
                    state(
                        s.t_s,
                        tr.pos_ned_m + rng.normal(0.0, sp, 3),
                        tr.vel_ned_mps + rng.normal(0.0, sv, 3),
                        sp,
                        sv,
                    )
                )
                ages = coast.slot_ages_s(s.t_s)
                slot = min(range(len(ages)), key=lambda i: ages[i] or 0.0)
                due += [(s.t_s + a, a, f"ins{slot}") for a in AGES_S]
                due.sort()
        elif isinstance(s, GnssFix) and s.receiver_id == 0:
            while due and s.t_s >= due[0][0]:
                _, age, name = due.pop(0)
                ref = coast.references(s.t_s).get(name)
                if ref is None or not isinstance(ref, CoastState):
                    continue
                if abs((s.t_s - ref.anchor_t_s) - age) > 0.2:
                    continue  # that slot was re-anchored meanwhile
                e = ref.pos_ned_m - flight.truth.at(s.t_s).pos_ned_m
                out[age].append(float(e @ np.linalg.solve(ref.pos_cov_ned_m2, e)))
    return out


@pytest.fixture(scope="module")
def nees() -> dict[str, dict[float, list[float]]]:
    res: dict[str, dict[float, list[float]]] = {}
    for grade in ("tactical", "mems"):
        res[grade] = {a: [] for a in AGES_S}
        for seed in SEEDS:
            for a, v in nees_vs_truth(grade, seed).items():
                res[grade][a] += v
    return res


@pytest.mark.parametrize("grade", ["tactical", "mems"])
def test_prediction_errors_are_chi_square_consistent(
    grade: str, nees: dict[str, dict[float, list[float]]]
) -> None:
    """Mean NEES of the 3-D position error at each age inside the two-sided 99 % interval of
    chi2(3 F) / F, F the number of flights (the slots of one flight share its IMU bias and
    attitude error, so the flights, not the slots, are the independent samples)."""
    f = len(SEEDS)
    lo, hi = chi2.ppf(0.005, 3 * f) / f, chi2.ppf(0.995, 3 * f) / f
    for age in AGES_S:
        v = np.array(nees[grade][age])
        assert v.size >= 2 * f, (age, v.size)
        assert lo <= v.mean() <= hi, (grade, age, v.mean(), lo, hi)
    pooled = np.concatenate([nees[grade][a] for a in AGES_S])
    # no gross outliers: each NEES below the chi2(3) quantile at 1e-4
    assert pooled.max() < chi2.isf(1e-4, 3), pooled.max()
