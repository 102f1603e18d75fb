"""The integrity monitor: FDE, separation, protection levels, alerts, reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.integrity.coast import CoastState
from companion.integrity.fde.separation import SeparationResult
from companion.integrity.monitor import IntegrityConfig, IntegrityMonitor
from companion.integrity.protection.limits import ApproachCategory, FlightPhase
from companion.integrity.protection.phase import PhaseConfig
from companion.nav.frames import LocalFrame
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.sim.integrity_approaches import ApproachSpec, Fault, SyntheticReference, run_approach
from companion.types import (
    Alert,
    AlertCode,
    FixType,
    GnssFix,
    IntegrityReport,
    NamedValue,
    NavMode,
    NavSolution,
)

FIELD = 110.0


def cat2_config(**kw: object) -> IntegrityConfig:
    return IntegrityConfig(
        approach_category=ApproachCategory.CAT_II,
        phase=PhaseConfig(field_elevation_msl_m=FIELD),
        **kw,  # type: ignore[arg-type]
    )


def fix(t: float, rid: int = 0) -> GnssFix:
    return GnssFix(
        t, t, rid, FixType.RTK_FIXED, 0.0, 0.0, 0.0, None, None, 0.0, None,
        None, None, None, None, None, None,
    )  # fmt: skip


def meas(t: float, pos: np.ndarray, rid: int = 0, sigma: float = 0.03) -> GnssMeasurement:
    nan3 = np.full(3, np.nan)
    return GnssMeasurement(t, pos, np.full(3, sigma**2), nan3, nan3, FixType.RTK_FIXED, rid)


def update(t: float, nis: float, fused: bool = True) -> GnssUpdate:
    return GnssUpdate(t, fused, nis, 3, 16.3, np.zeros(3), np.eye(3))


def solution(t: float, sigma_v: float = 0.03, height: float = 200.0) -> NavSolution:
    return NavSolution(
        t_s=t,
        lat_rad=0.0,
        lon_rad=0.0,
        alt_msl_m=FIELD + height,
        vel_ned_mps=np.array([70.0, 0.0, 3.7]),
        pos_cov_ned_m2=np.diag([0.0004, 0.0004, sigma_v**2]),
        vel_cov_ned_m2ps2=np.eye(3) * 0.01,
        yaw_rad=None,
        mode=NavMode.NORMAL,
        fix_type=FixType.RTK_FIXED,
        satellites=20,
    )


def alerts(outs: list[object], code: AlertCode) -> list[Alert]:
    return [o for o in outs if isinstance(o, Alert) and o.code is code]


# ----------------------------------------------------------------------------- config


@pytest.mark.parametrize(
    "kwargs",
    [
        {"false_alarm_prob": 0.0},
        {"slope_false_alarm_prob": 1.0},
        {"integrity_risk_vertical": -1.0},
        {"separation_window_s": 0.0},
        {"recovery_s": math.nan},
        {"min_window_points": 2},
        {"category_upgrade_dwell_s": -1.0},
        {"approach_category": 2},
    ],
)
def test_config_validation(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        IntegrityConfig(**kwargs)  # type: ignore[arg-type]


def test_k_factors_from_the_default_risks() -> None:
    mon = IntegrityMonitor()
    assert mon.k_h == pytest.approx(6.18, abs=0.005)
    assert mon.k_v == pytest.approx(5.33, abs=0.005)


# ----------------------------------------------------------------------------- fix level


def test_a_failed_fix_is_excluded_counted_and_alerted_once() -> None:
    mon = IntegrityMonitor(cat2_config())
    pos = np.zeros(3)
    assert mon.on_fix(fix(0.0), meas(0.0, pos), update(0.0, 2.0)) == []
    outs = mon.on_fix(fix(0.1), meas(0.1, pos), update(0.1, 500.0, fused=False))
    faults = alerts(outs, AlertCode.FAULT)
    assert len(faults) == 1 and "rx0" in faults[0].text and "innovation" in faults[0].text
    assert mon.exclude(0) and mon.fault_detected and not mon.fault_unresolved
    outs = mon.on_fix(fix(0.2), meas(0.2, pos), update(0.2, 600.0, fused=False))
    assert alerts(outs, AlertCode.FAULT) == []  # no repeat while the fault lasts
    assert mon.stats["fix_innovation"] == 2
    # clean fixes for recovery_s: re-admitted
    t = 0.3
    while t < 0.2 + mon.config.recovery_s + 0.15:
        mon.on_fix(fix(t), meas(t, pos), update(t, 2.0))
        t += 0.1
    assert not mon.exclude(0) and not mon.fault_detected
    assert mon.accuracy_floor_m() == (0.0, 0.0)


def test_a_failed_fix_the_navigator_fused_leaves_the_fault_unresolved() -> None:
    mon = IntegrityMonitor(cat2_config())
    mon.on_fix(fix(0.0), meas(0.0, np.zeros(3)), update(0.0, 1.0))
    outs = mon.on_fix(fix(0.1), meas(0.1, np.zeros(3)), update(0.1, 80.0, fused=True))
    assert alerts(outs, AlertCode.FAULT)
    assert mon.fault_unresolved
    outs = mon.on_solution(solution(0.1))
    integ = alerts(outs, AlertCode.INTEGRITY)
    assert integ and integ[0].severity.name == "CRITICAL" and not mon.integrity_ok


def test_potential_ellipsoid_test() -> None:
    mon = IntegrityMonitor(cat2_config())
    pred = NavState(
        0.0, np.zeros(3), np.array([70.0, 0.0, 0.0]), np.eye(3) * 0.01, np.eye(3) * 0.01
    )
    ok = mon.on_fix(fix(0.1), meas(0.1, np.array([7.0, 0.0, 0.0])), None, predicted=pred)
    assert ok == [] and not mon.exclude(0)
    bad = mon.on_fix(fix(0.1), meas(0.1, np.array([9.0, 0.0, 0.0])), None, predicted=pred)
    assert alerts(bad, AlertCode.FAULT) and "ellipsoid" in alerts(bad, AlertCode.FAULT)[0].text


def test_bad_measurement_is_rejected_and_counted() -> None:
    mon = IntegrityMonitor()
    outs = mon.on_fix(fix(0.0), meas(0.0, np.array([np.nan, 0.0, 0.0])), None)
    assert outs == [] and mon.stats["bad_measurement"] == 1
    m = meas(0.1, np.zeros(3))
    bad_var = GnssMeasurement(
        0.1, m.pos_ned_m, np.array([0.0, 1.0, 1.0]), m.vel_ned_mps, m.vel_var_ned_m2ps2,
        m.fix_type,
    )  # fmt: skip
    assert mon.on_fix(fix(0.1), bad_var, None) == [] and mon.stats["bad_measurement"] == 2


def test_reference_separation_blames_the_receiver() -> None:
    mon = IntegrityMonitor(cat2_config())
    ref = NavState(1.0, np.zeros(3), np.zeros(3), np.eye(3) * 0.01, np.eye(3) * 1e-4)
    mon.on_fix(fix(1.0), meas(1.0, np.zeros(3)), None, references={"ins": ref})
    assert not mon.exclude(0)
    ref2 = NavState(1.1, np.zeros(3), np.zeros(3), np.eye(3) * 0.01, np.eye(3) * 1e-4)
    outs = mon.on_fix(fix(1.1), meas(1.1, np.array([0, 0, 2.0])), None, references={"ins": ref2})
    assert mon.exclude(0) and "ref:ins" in alerts(outs, AlertCode.FAULT)[0].text


# ----------------------------------------------------------------------------- solutions


def test_reports_and_named_values_at_one_hertz() -> None:
    mon = IntegrityMonitor(cat2_config())
    outs: list[object] = []
    for k in range(100):  # 10 s at 10 Hz
        outs += mon.on_solution(solution(0.1 * k))
    reports = [o for o in outs if isinstance(o, IntegrityReport)]
    names = [o.name for o in outs if isinstance(o, NamedValue)]
    assert len(reports) == 10
    assert names.count("CMP_HPL") == names.count("CMP_VPL") == names.count("CMP_CAT") == 10
    assert all(r.integrity_ok and not r.fault_detected for r in reports)
    hpl = next(o for o in outs if isinstance(o, NamedValue) and o.name == "CMP_HPL")
    assert hpl.value == pytest.approx(6.18 * 0.02, rel=1e-3)
    assert mon.phase is FlightPhase.APPROACH
    assert alerts(outs, AlertCode.INTEGRITY) == []


def test_integrity_lost_when_vpl_exceeds_val_and_restored() -> None:
    mon = IntegrityMonitor(cat2_config())
    assert mon.on_solution(solution(0.0)) is not None and mon.integrity_ok
    sigma_bad = 5.4 / 5.33 * 1.01  # VPL just above the CAT II VAL
    outs = mon.on_solution(solution(0.1, sigma_v=sigma_bad))
    lost = alerts(outs, AlertCode.INTEGRITY)
    assert len(lost) == 1 and "VPL" in lost[0].text and not mon.integrity_ok
    assert alerts(mon.on_solution(solution(0.2, sigma_v=sigma_bad)), AlertCode.INTEGRITY) == []
    # restored at once for publication, announced once it has held (5 s): a VPL crossing its
    # limit back and forth meanwhile is the one loss already announced
    assert alerts(mon.on_solution(solution(0.3)), AlertCode.INTEGRITY) == [] and mon.integrity_ok
    flaps = [
        mon.on_solution(solution(0.4 + 0.1 * k, sigma_v=sigma_bad if k % 2 else 1.0))
        for k in range(20)
    ]
    assert [a for out in flaps for a in alerts(out, AlertCode.INTEGRITY)] == []
    restore_dwell_s = cat2_config().integrity_restore_dwell_s
    t_ok = 2.5
    quiet = [
        alerts(mon.on_solution(solution(t_ok + 0.1 * k)), AlertCode.INTEGRITY)
        for k in range(int(restore_dwell_s / 0.1))
    ]
    assert all(q == [] for q in quiet)
    back = alerts(mon.on_solution(solution(t_ok + restore_dwell_s)), AlertCode.INTEGRITY)
    assert len(back) == 1 and back[0].text.startswith("restored") and mon.integrity_ok
    # the same VPL en route is no problem (no vertical limit there)
    mon2 = IntegrityMonitor(cat2_config())
    mon2.on_solution(solution(0.0, sigma_v=sigma_bad, height=2000.0))
    assert mon2.integrity_ok and mon2.phase is FlightPhase.ENROUTE


def test_category_downgrades_at_once_and_upgrades_after_the_dwell() -> None:
    mon = IntegrityMonitor(cat2_config())
    outs: list[object] = []
    t = 0.0
    while t < 6.0:
        outs += mon.on_solution(solution(t))
        t += 0.1
    up = alerts(outs, AlertCode.CAT)
    assert len(up) == 1 and up[0].text == "none -> CAT III"
    assert up[0].t_s == pytest.approx(mon.config.category_upgrade_dwell_s, abs=0.11)
    down = alerts(mon.on_solution(solution(t, sigma_v=0.6)), AlertCode.CAT)
    assert len(down) == 1 and down[0].text == "CAT III -> CAT II"
    assert mon.category is ApproachCategory.CAT_II


def test_lost_navigation_means_no_integrity() -> None:
    mon = IntegrityMonitor(cat2_config())
    sol = solution(0.0)
    lost = NavSolution(
        sol.t_s, sol.lat_rad, sol.lon_rad, sol.alt_msl_m, sol.vel_ned_mps, sol.pos_cov_ned_m2,
        sol.vel_cov_ned_m2ps2, None, NavMode.LOST, FixType.NO_FIX, 0,
    )  # fmt: skip
    assert alerts(mon.on_solution(lost), AlertCode.INTEGRITY) and not mon.integrity_ok


def test_shift_frame_keeps_exclusions() -> None:
    mon = IntegrityMonitor(cat2_config())
    mon.on_fix(fix(0.0), meas(0.0, np.zeros(3)), update(0.0, 1.0))
    mon.on_fix(fix(0.1), meas(0.1, np.zeros(3)), update(0.1, 900.0, fused=False))
    old = LocalFrame(0.9, 0.36, 100.0)
    new = LocalFrame(0.9001, 0.3601, 100.0)
    mon.shift_frame(old, new)
    assert mon.exclude(0)
    mon.reset()
    assert not mon.exclude(0) and not mon.fault_detected


# ----------------------------------------------------------------------------- synthetic runs


def run(faults: tuple[Fault, ...], receivers: int = 2, seed: int = 1, **kw: object):  # noqa: ANN201
    spec = ApproachSpec(receivers=receivers, faults=faults, **kw)  # type: ignore[arg-type]
    return run_approach(spec, IntegrityMonitor(cat2_config()), np.random.default_rng(seed))


def test_nominal_dual_receiver_approaches_raise_nothing() -> None:
    for seed in range(3):
        res = run((), seed=seed)
        assert res.alerts == () and res.baseline_alerts == ()
        assert res.monitor.category is ApproachCategory.CAT_III


@pytest.mark.parametrize(
    "vector", [(10.0, 0.0, 0.0), (0.0, 0.0, 5.4), (0.0, 17.0, 0.0)], ids=["10m", "VAL", "HAL"]
)
@pytest.mark.parametrize("receivers", [1, 2])
def test_steps_at_the_alert_limits_are_alerted_within_a_second(
    vector: tuple[float, float, float], receivers: int
) -> None:
    res = run((Fault("step", 40.0, vector),), receivers=receivers)
    assert res.first_alert_s is not None
    assert 40.0 <= res.first_alert_s <= 41.0
    assert not [a for a in res.alerts if a < 40.0]


def test_4cm_ramp_caught_before_1m_where_the_plain_test_is_blind() -> None:
    res = run((Fault("ramp", 40.0, (0.0, 0.0, 0.04)),))
    assert res.first_alert_s is not None
    assert 0.04 * (res.first_alert_s - 40.0) < 1.0
    assert res.baseline_first_s is None  # the navigator follows the ramp
    assert not res.monitor.integrity_ok
    # the published accuracy must widen to the disagreement (the ramp reached ~3 m)
    floor_h, floor_v = res.monitor.accuracy_floor_m()
    assert floor_v > 2.0 and floor_h < floor_v


def test_1m_dither_caught_where_the_plain_test_is_blind() -> None:
    res = run((Fault("dither", 40.0, (0.0, 0.0, 1.0), amplitude_m=1.0, period_s=20.0),))
    assert res.first_alert_s is not None and res.first_alert_s - 40.0 < 5.0
    assert res.baseline_first_s is None


@pytest.mark.parametrize(
    "fault",
    [
        Fault("step", 40.0, (1.0, 0.0, -2.0)),
        Fault("ramp", 40.0, (0.0, 0.03, 0.04)),
        Fault("dither", 40.0, (0.0, 0.0, 2.0), amplitude_m=1.0, period_s=20.0),
    ],
    ids=["step", "ramp", "dither"],
)
def test_a_fault_as_a_simulator_event_offsets_the_fixes_the_same(fault: Fault) -> None:
    from companion.sim import make_scenario
    from companion.sim.sensors import fault_offset_ned_m

    sc = make_scenario("approach", events=(fault.as_event(1000.0),))
    times = np.array([39.9, 40.0, 45.3, 61.0])
    got = np.array([fault_offset_ned_m(sc, 0, float(t)) for t in times])
    np.testing.assert_allclose(got, fault.offset_ned_m(times), rtol=0.0, atol=1e-12)


def test_ramp_on_a_navigator_fusing_both_receivers_is_not_pinned_on_the_good_one() -> None:
    res = run((Fault("ramp", 40.0, (0.0, 0.0, 0.04)),), fuse_all=True)
    assert res.first_alert_s is not None and 0.04 * (res.first_alert_s - 40.0) < 1.0
    assert not res.monitor.exclude(1)


# ----------------------------------------------------------------------------- inertial references


def coast_ref(t: float, pos: np.ndarray, anchor_t: float, sigma_v: float = 0.01) -> CoastState:
    tau = t - anchor_t
    s_a = np.eye(3) * 1e-8
    return CoastState(
        t, pos, np.zeros(3), np.eye(3) * (0.02**2 + (sigma_v * tau) ** 2),
        np.eye(3) * sigma_v**2, None, anchor_t, s_a, 0.0,
    )  # fmt: skip


def test_a_reanchored_reference_restarts_its_series() -> None:
    """A slot that drifted 60 cm (inside its covariance) re-anchors back onto the truth:
    the step is not a fault. Without the restart the window sees a 60 cm jump."""

    def run(reanchor: bool) -> IntegrityMonitor:
        mon = IntegrityMonitor(cat2_config())
        for k in range(300):
            t = 0.1 * k
            jumped_at = 20.0 if t >= 20.0 else 0.0
            drift = 0.03 * (t - jumped_at)  # 3 cm/s, as its velocity sigma allows
            anchored_at = jumped_at if reanchor else 0.0
            ref = coast_ref(t, np.array([0.0, 0.0, drift]), anchored_at, sigma_v=0.03)
            mon.on_fix(fix(t), meas(t, np.zeros(3)), None, references={"ins0": ref})
        return mon

    good = run(reanchor=True)
    assert good.stats["reference_reanchored"] == 1
    assert good.stats["fault_fixes"] == 0 and not good.exclude(0)
    bad = run(reanchor=False)  # the same jump without a new anchor time is a fault
    assert bad.stats["fault_fixes"] > 0


def test_reference_drift_within_its_velocity_sigma_is_no_slope_fault() -> None:
    """A 5 cm/s drift of a reference whose velocity sigma is 2 cm/s passes; the same
    series from a reference that claims no velocity error fails the slope test."""
    outcome = {}
    for sigma_v in (0.02, 1e-4):
        mon = IntegrityMonitor(cat2_config())
        for k in range(200):
            t = 0.1 * k
            ref = coast_ref(t, np.array([0.0, 0.0, 0.05 * t]), 0.0, sigma_v)
            m = meas(t, np.zeros(3), sigma=0.03)
            mon.on_fix(fix(t), m, None, references={"ins0": ref})
        outcome[sigma_v] = mon.stats["separation_slope"]
    assert outcome[0.02] == 0 and outcome[1e-4] > 0


def run_ref(faults: tuple[Fault, ...], receivers: int, seed: int, **ref_kw: object):  # noqa: ANN201
    spec = ApproachSpec(receivers=receivers, faults=faults)
    rng = np.random.default_rng(seed)
    ref = SyntheticReference(np.random.default_rng(seed + 100), **ref_kw)  # type: ignore[arg-type]
    t0 = faults[0].t_start_s if faults else 0.0
    return run_approach(spec, IntegrityMonitor(cat2_config()), rng, t_from_s=t0, reference=ref)


def test_one_receiver_with_an_inertial_reference_catches_a_4cm_ramp_before_1m() -> None:
    for seed in range(2):
        res = run_ref((Fault("ramp", 40.0, (0.0, 0.0, 0.04)),), 1, seed)
        assert res.first_alert_s is not None and 0.04 * (res.first_alert_s - 40.0) < 1.0
        assert not [a for a in res.alerts if a < 40.0]
        assert res.baseline_first_s is None  # the navigator follows the ramp
        assert res.monitor.exclude(0)
    res = run_ref((Fault("dither", 40.0, (0.0, 0.0, 1.0), amplitude_m=1.0),), 1, 5)
    assert res.first_alert_s is not None and res.first_alert_s - 40.0 < 5.0


def test_one_receiver_with_an_inertial_reference_raises_nothing_nominally() -> None:
    for seed in range(3):
        res = run_ref((), 1, seed)
        assert res.alerts == ()
        assert res.monitor.stats["reference_reanchored"] > 0


def test_two_receivers_and_a_reference_exclude_the_ramping_receiver() -> None:
    """The receiver pair detects the ramp first (unresolved: nothing yet tells which);
    a reference anchored well before (a sharp one: 1e-4 m/s^2 of acceleration error) then
    pins it on rx0; rx1 is never excluded."""
    for seed in range(3):
        res = run_ref((Fault("ramp", 40.0, (0.0, 0.0, 0.04)),), 2, seed, acc_sigma_mps2=(1e-4,) * 3)
        assert res.first_alert_s is not None and 0.04 * (res.first_alert_s - 40.0) < 1.0
        mon = res.monitor
        assert mon.exclude(0) and not mon.exclude(1)
        assert "rx1 excluded" not in " ".join(str(a) for a in res.alerts)


def test_arbitration_needs_a_failed_test_against_a_third_solution() -> None:
    attribution = IntegrityMonitor(cat2_config()).fde.attribution
    pairs = attribution.pairs
    mk = lambda t, fail: SeparationResult(  # noqa: E731
        t, np.zeros(3), 40.0 if fail else 1.0, 35.4, np.zeros(3), math.nan, math.nan, 1, ()
    )
    now = 10.0
    key = ("rx0", "rx1")
    pairs.latest = {("rx0", "ref:ins0"): mk(10.0, True), ("rx1", "ref:ins0"): mk(10.0, False)}
    assert attribution.arbitrate(0, 1, key, set(), now) == 0
    pairs.latest = {("rx0", "ref:ins0"): mk(10.0, False), ("rx1", "ref:ins0"): mk(10.0, False)}
    assert attribution.arbitrate(0, 1, key, set(), now) is None  # both consistent: nothing tells
    pairs.latest = {("rx0", "ref:ins0"): mk(10.0, True), ("rx1", "ref:ins0"): mk(10.0, True)}
    assert attribution.arbitrate(0, 1, key, set(), now) is None  # both fail: the ref may be off
    pairs.latest = {("rx0", "ref:ins0"): mk(-5.0, True), ("rx1", "ref:ins0"): mk(10.0, False)}
    assert attribution.arbitrate(0, 1, key, set(), now) is None  # stale evidence does not count


def test_a_reference_anchored_on_the_faulty_receiver_does_not_blame_the_good_one() -> None:
    """rx0 ramps from 40 s; a reference re-anchored at 42 s from a navigator that followed
    rx0 carries its ramp and disagrees with rx1. It was anchored less than one window
    before the receivers' disagreement was detected, and rx1 is not the fused receiver:
    it does not count, rx1 stays in (the fault is unresolved)."""
    mon = IntegrityMonitor(cat2_config())
    rng = np.random.default_rng(3)
    rate = np.array([0.0, 0.0, 0.04])
    for k in range(1, 900):
        t = 0.1 * k
        ramp = rate * max(t - 40.0, 0.0)
        anchor_t = 42.0 if t >= 42.0 else 0.0
        ref_err = rate * 2.0 + rate * (t - 42.0) if t >= 42.0 else np.zeros(3)
        ref = coast_ref(t, ref_err, anchor_t, sigma_v=0.005)
        for rid in (0, 1):
            pos = rng.normal(0.0, 0.01, 3) + (ramp if rid == 0 else 0.0)
            mon.on_fix(fix(t, rid), meas(t, pos, rid), None, references={"ins0": ref})
        assert not mon.exclude(1), t
    assert mon.fault_unresolved
    assert mon.stats["reference_untrusted"] + mon.stats["reference_vs_unfused"] > 0


def test_a_fix_type_change_restarts_the_receivers_series() -> None:
    mon = IntegrityMonitor(cat2_config())
    key = ("rx0", "ref:ins0")
    for k in range(60):
        t = 0.1 * k
        m = meas(t, np.zeros(3))
        if k >= 50:  # RTK fixed -> float
            m = GnssMeasurement(t, m.pos_ned_m, np.full(3, 0.3**2), m.vel_ned_mps,
                                m.vel_var_ned_m2ps2, FixType.RTK_FLOAT, 0)  # fmt: skip
        mon.on_fix(fix(t), m, None, references={"ins0": coast_ref(t, np.zeros(3), 0.0)})
        if k == 49:
            assert mon.fde.pairs.latest[key].window_points == 50
    assert mon.stats["series_restarted_fix_type"] == 1
    assert mon.fde.pairs.latest[key].window_points == 10
