"""The spoofing monitor against known truth: the IMU's increments against closed forms, the
drag test consistent without a drag and detecting one within its own bound, a step not
taken for a drag, an episode's reference honest, re-admission, the receiver's own flag."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from companion.integrity.spoof import SpoofConfig, SpoofMonitor
from companion.integrity.spoof.inertial import InertialIncrements
from companion.nav.navigator import GnssMeasurement, NavState
from companion.nav.rotations import euler_to_mat_nb
from companion.types import (
    AlertCode,
    AttitudeSample,
    FixType,
    GnssFix,
    ImuSample,
    InterferenceState,
)

G = 9.80665
IMU_HZ = 50.0
ATT_EVERY = 2  # attitude at 25 Hz
FIX_EVERY = 10  # fixes at 5 Hz


def _imu(t: float, f_b: np.ndarray, w_b: np.ndarray | None = None) -> ImuSample:
    return ImuSample(t, t, f_b, np.zeros(3) if w_b is None else w_b)


def _att(t: float, roll: float, pitch: float, yaw: float, rate: np.ndarray) -> AttitudeSample:
    return AttitudeSample(t, t, roll, pitch, yaw, rate)


def test_increments_integrate_a_constant_specific_force() -> None:
    """Level, yaw 30 deg, a constant body specific force: V, P, W, WW in closed form."""
    inc = InertialIncrements(G)
    yaw = math.radians(30.0)
    f_b = np.array([0.4, -0.2, -G])
    inc.on_attitude(_att(0.0, 0.0, 0.0, yaw, np.zeros(3)))
    for k in range(501):
        inc.on_imu(_imu(k / 100.0, f_b))
    c = euler_to_mat_nb(0.0, 0.0, yaw)
    a_n = c @ f_b + np.array([0.0, 0.0, G])
    at0, at = inc.at(0.0), inc.at(5.0)
    assert at0 is not None and at is not None
    t = 5.0
    np.testing.assert_allclose(at.vel - at0.vel, a_n * t, atol=1e-9)
    np.testing.assert_allclose(at.pos - at0.pos, 0.5 * a_n * t * t, atol=1e-9)
    np.testing.assert_allclose(at.w - at0.w, c[:2, :] * t, atol=1e-12)
    np.testing.assert_allclose(at.ww - at0.ww, 0.5 * c[:2, :] * t * t, atol=1e-9)
    assert at.turn - at0.turn == pytest.approx(0.0)


def test_increments_break_at_an_imu_gap() -> None:
    inc = InertialIncrements(G)
    inc.on_attitude(_att(0.0, 0.0, 0.0, 0.0, np.zeros(3)))
    inc.on_imu(_imu(0.0, np.array([0.0, 0.0, -G])))
    inc.on_imu(_imu(0.02, np.array([0.0, 0.0, -G])))
    first = inc.epoch
    inc.on_imu(_imu(2.0, np.array([0.0, 0.0, -G])))  # longer than MAX_IMU_GAP_S
    assert inc.epoch == first + 1 and inc.stats["imu_gap"] == 1
    assert inc.at(0.02) is None  # the history before the gap is gone


@dataclass
class Flight:
    """A synthetic level flight circling at 20 m/s: what the monitor is fed."""

    samples: list[object]
    truth_pos: dict[float, np.ndarray]
    truth_vel: dict[float, np.ndarray]


def fly(
    duration_s: float,
    seed: int,
    drag: tuple[float, float, float] | None = None,
    step: tuple[float, float] | None = None,
    acc_noise: float = 0.05,
    vel_noise: float = 0.05,
    lag_s: float = 0.0,
) -> Flight:
    """Samples (attitude, IMU, fixes) of a level turn at 20 m/s, yaw rate 0.05 rad/s; IMU
    white noise ``acc_noise`` per sample, GNSS velocity noise ``vel_noise``, a body-frame
    accelerometer bias. ``drag``: (onset s, acceleration m/s^2, release s) of a consistent
    drag of position and velocity, to at most 5 m/s; ``step``: (time s, m/s) a step of
    the reported velocity alone (what a spoofer letting go looks like); ``lag_s``: the
    fixes report the truth that long before their time."""
    rng = np.random.default_rng(seed)
    speed, rate = 20.0, 0.05
    bias_b = np.array([0.05, -0.03, 0.02])
    samples: list[object] = []
    truth_pos: dict[float, np.ndarray] = {}
    truth_vel: dict[float, np.ndarray] = {}
    direction = np.array([math.cos(seed), math.sin(seed), 0.0])
    n = int(duration_s * IMU_HZ)
    for k in range(n + 1):
        t = k / IMU_HZ
        yaw = rate * t
        pos = speed / rate * np.array([math.sin(yaw), 1.0 - math.cos(yaw), 0.0])
        vel = speed * np.array([math.cos(yaw), math.sin(yaw), 0.0])
        acc = speed * rate * np.array([-math.sin(yaw), math.cos(yaw), 0.0])
        c = euler_to_mat_nb(0.0, 0.0, yaw)
        f_b = c.T @ (acc - np.array([0.0, 0.0, G])) + bias_b + rng.normal(0.0, acc_noise, 3)
        w_b = np.array([0.0, 0.0, rate])
        if k % ATT_EVERY == 0:
            samples.append(_att(t, 0.0, 0.0, yaw, w_b))
        samples.append(_imu(t, f_b, w_b))
        if k % FIX_EVERY == 0 and t > 0.0:
            yaw_v = rate * (t - lag_s)
            p_rep = speed / rate * np.array([math.sin(yaw_v), 1.0 - math.cos(yaw_v), 0.0])
            v_rep = speed * np.array([math.cos(yaw_v), math.sin(yaw_v), 0.0])
            if drag is not None and drag[0] < t < drag[2]:
                tau = t - drag[0]
                t_max = 5.0 / drag[1]
                dv = min(drag[1] * tau, 5.0)
                dp = 0.5 * drag[1] * min(tau, t_max) ** 2 + 5.0 * max(tau - t_max, 0.0)
                p_rep, v_rep = p_rep + dp * direction, v_rep + dv * direction
            if step is not None and t >= step[0]:
                v_rep = v_rep + step[1] * direction
            v_rep[:2] += rng.normal(0.0, vel_noise, 2)
            samples.append((t, p_rep, v_rep))
            truth_pos[round(t, 6)] = pos
            truth_vel[round(t, 6)] = vel
    return Flight(samples, truth_pos, truth_vel)


def _fix(t: float, vel: np.ndarray, rid: int = 0, placed_s: float = 0.0) -> GnssFix:
    return GnssFix(
        t_s=t, t_rx_s=t, receiver_id=rid, fix_type=FixType.FIX_3D, lat_rad=0.0, lon_rad=0.0,
        alt_msl_m=100.0, alt_hae_m=None, vel_ne_mps=vel[:2].copy(),
        ground_speed_mps=float(np.hypot(*vel[:2])), course_rad=0.0, h_acc_m=2.0,
        v_acc_m=3.0, vel_acc_mps=0.1, hdop=1.0, vdop=1.5, satellites=12, placed_s=placed_s,
    )  # fmt: skip


def run(
    flight: Flight,
    config: SpoofConfig | None = None,
    flags: dict[float, bool] | None = None,
    placed: tuple[float, float, bool] | None = None,
):
    """Feed the monitor; the navigator is the truth plus 1 m / 0.1 m/s of honest error (a
    navigator that follows a spoofer is what the monitor must not need). ``placed``: (from
    s, lag s, told) the service places the fixes that much earlier from then on, and
    says so in ``GnssFix.placed_s`` if told."""
    mon = SpoofMonitor(config or SpoofConfig.for_grade("mems"))
    alerts, rollbacks, stats = [], [], []
    for s in flight.samples:
        if isinstance(s, AttitudeSample):
            mon.on_attitude(s)
        elif isinstance(s, ImuSample):
            mon.on_imu(s)
        else:
            t, p_rep, v_rep = s
            key = round(t, 6)
            placed_s = placed[1] if placed is not None and t >= placed[0] else 0.0
            told_s = placed_s if placed is not None and placed[2] else 0.0
            nav = NavState(
                t, flight.truth_pos[key], flight.truth_vel[key], np.eye(3), 0.01 * np.eye(3)
            )
            t = t - placed_s
            meas = GnssMeasurement(
                t, p_rep, np.full(3, 4.0), v_rep, np.full(3, 0.01), FixType.FIX_3D, 0
            )
            flagged = bool(flags and any(a <= t < b for a, b in flags.items()))
            step = mon.on_fix(
                _fix(t, v_rep, placed_s=told_s),
                meas,
                nav,
                airborne=True,
                own_verdict=InterferenceState.DETECTED if flagged else InterferenceState.CLEAN,
            )
            alerts += step.alerts
            if step.rollback is not None:
                rollbacks.append((t, step.rollback))
            rx = mon._receivers.get(0)
            if rx is not None and rx.last is not None and rx.last.tested:
                stats.append(rx.last.stat / rx.last.threshold)
    return mon, alerts, rollbacks, np.array(stats)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_no_drag_no_alarm_and_the_statistic_is_consistent(seed: int) -> None:
    """Ten minutes without a drag: no SPOOF, no failed fix, and the calibrated statistic's
    mean near its chi-square (2 dof) mean (2, i.e. 2 / threshold here)."""
    mon, alerts, _, stats = run(fly(600.0, seed))
    assert not alerts
    assert mon.stats["failed"] == 0
    assert len(stats) > 2000
    thr = mon._receivers[0].test.threshold
    assert 0.3 < float(np.mean(stats)) * thr / 2.0 < 1.5


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_drag_is_detected_within_its_bound_and_rolled_back(seed: int) -> None:
    """0.5 m/s^2 from 200 s: SPOOF before the drag's separation reaches twice the smallest
    the test said it could see, the error at detection under 10 m; the rollback state is
    the truth within its covariance."""
    onset, a = 200.0, 0.5
    mon_before, *_ = run(fly(onset, seed))
    bound_5s = mon_before.detectable_mps2(0, 5.0)
    assert bound_5s < a  # a clean MEMS stream sees 0.5 m/s^2 within 5 s
    flight = fly(300.0, seed, drag=(onset, a, 400.0))
    mon, alerts, rollbacks, _ = run(flight)
    spoof = [al for al in alerts if al.code is AlertCode.SPOOF]
    assert spoof, "not detected"
    t_det = spoof[0].t_s
    assert onset < t_det < onset + 5.0
    assert 0.5 * a * (t_det - onset) ** 2 < 10.0
    t, state = rollbacks[0]
    err = state.pos_ned_m[:2] - flight.truth_pos[round(t, 6)][:2]
    sigma = math.sqrt(max(np.linalg.eigvalsh(state.pos_cov_ned_m2[:2, :2])))
    assert float(np.hypot(*err)) < 3.0 * sigma + 1.0
    assert mon.excluded(0) and mon.hpl_floor_m() > 0.0


def test_a_held_receiver_is_readmitted_once_it_agrees_again() -> None:
    """The drag lets go after 20 s (the reported track back on the truth): SPOOF_END,
    verified by a reference that had seen the separation; not before the release."""
    flight = fly(300.0, 4, drag=(200.0, 0.5, 220.0))
    mon, alerts, _, _ = run(flight)
    codes = [(al.code, al.t_s) for al in alerts]
    assert codes[0][0] is AlertCode.SPOOF
    ends = [t for code, t in codes if code is AlertCode.SPOOF_END]
    assert ends and ends[0] > 220.0
    assert not mon.excluded(0) and 0 not in mon.episodes


def test_a_drag_that_continues_keeps_the_receiver_out() -> None:
    flight = fly(330.0, 5, drag=(200.0, 0.5, 1000.0))
    mon, alerts, _, _ = run(flight)
    assert [al.code for al in alerts] == [AlertCode.SPOOF]
    assert mon.excluded(0)
    assert mon.state() is InterferenceState.MITIGATED


def test_a_velocity_step_is_not_taken_for_a_drag() -> None:
    """A step of the reported velocity alone (a spoofer letting go, or a glitch): the IMU
    cannot say which side is true; no SPOOF, counted as a step."""
    mon, alerts, _, _ = run(fly(300.0, 6, step=(250.0, 5.0)))
    assert not [al for al in alerts if al.code is AlertCode.SPOOF]
    assert mon.stats["steps"] >= 1


def test_a_receiver_that_says_it_is_spoofed_is_held_until_its_flag_clears() -> None:
    """DETECTED from the receiver's own flags from 200 s to 230 s, its track honest: held at
    once, re-admitted only after the flag has cleared and its fixes agree for readmit_s."""
    mon, alerts, _, _ = run(fly(300.0, 7), flags={200.0: 230.0})
    codes = [(al.code, al.t_s, al.text) for al in alerts]
    assert codes[0][0] is AlertCode.SPOOF and "says it is spoofed" in codes[0][2]
    assert 200.0 <= codes[0][1] < 201.0
    ends = [(t, text) for code, t, text in codes if code is AlertCode.SPOOF_END]
    assert ends and ends[0][0] >= 230.0 + mon.config.readmit_s - 0.5
    # nothing ever separated: the IMU could not have seen a drag, the protection says so
    assert "cannot tell" in ends[0][1] and mon.hpl_floor_m() > 0.0 and not mon.excluded(0)


def test_the_service_placing_its_fixes_anew_is_not_a_drag() -> None:
    """Fixes valid 0.6 s before their stamps (a lag not yet measured, 3 sigma of the prior);
    at 150 s the service places them with it (its own change, told in ``GnssFix.placed_s``):
    the velocities the test compares with its references move by the turn's acceleration
    (1 m/s^2) times 0.6 s, which is known and taken out: no SPOOF, no failed fix. Not told,
    the same change fails the test (a step: no SPOOF either, but the test was blind)."""
    flight = fly(300.0, 9, lag_s=0.6)
    mon, alerts, _, stats = run(flight, placed=(150.0, 0.6, True))
    assert not alerts and mon.stats["failed"] == 0 and float(np.max(stats)) < 0.5
    untold, _, _, stats = run(flight, placed=(150.0, 0.6, False))
    assert untold.stats["failed"] > 0 and float(np.max(stats)) > 1.0


def test_a_grade_found_worse_widens_the_test_and_starts_it_again() -> None:
    """The engine's grade check found a 'tactical' IMU to be MEMS: the grade's larger
    figures are taken (none smaller), every test starts again; a second call changes
    nothing."""
    flight = fly(100.0, 10)
    mon, *_ = run(flight, SpoofConfig.for_grade("tactical"))
    assert mon._receivers[0].test.running
    mon.widen_grade("mems")
    mems = SpoofConfig.for_grade("mems")
    assert mon.config.acc_bias_z_sigma_mps2 == mems.acc_bias_z_sigma_mps2
    assert mon.config.tilt_rw_m2ps5 == mems.tilt_rw_m2ps5
    assert mon._receivers[0].test.config is mon.config
    assert not mon._receivers[0].test.running and mon.stats["grade_widened"] == 1
    mon.widen_grade("mems")
    assert mon.stats["grade_widened"] == 1


def test_clean_only_while_the_test_could_see_a_fast_drag() -> None:
    """GNSS_INTEGRITY's "clean" means the drag test would see 0.5 m/s^2 within 10 s: on a
    quiet stream once the wander is measured; with 3 m/s^2 of vibration per 50 Hz sample
    (0.18 m^2/s^3) it cannot, and the verdict is "unknown" with the bound published."""
    mon, alerts, _, _ = run(fly(300.0, 11))
    assert not alerts and mon.verified_mps2() <= 0.5
    assert mon.state() is InterferenceState.CLEAN
    noisy, alerts, _, _ = run(fly(300.0, 11, acc_noise=3.0))
    assert not alerts and noisy.stats["tested"] > 1000
    assert 0.5 < noisy.verified_mps2() < math.inf
    assert noisy.state() is InterferenceState.UNKNOWN


def test_off_means_no_test() -> None:
    mon, alerts, _, _ = run(fly(300.0, 8, drag=(200.0, 0.5, 1000.0)), SpoofConfig(enabled=False))
    assert not alerts and mon.stats["tested"] == 0
