"""Tests of the taxi heading correction (Markelov et al.) against simulated truth.

The streams come from a small generator of parked stands, straight legs and
turns (below): the truth heading is integrated from the yaw rate, the INS
heading carries a known error, the GNSS velocity follows the truth track
(plus an optional crab angle, bias and white noise) and arrives late.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pytest

from companion.nav.earth import radii_of_curvature_m
from companion.nav.heading import (
    HeadingConfig,
    HeadingCorrector,
    HeadingPhase,
    RunningStats,
    yaw_rate_radps,
)
from companion.nav.heading.criteria import park_bias_verdict
from companion.nav.rotations import wrap_pi
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    FixType,
    GnssFix,
    HeadingAction,
    HeadingCommand,
    NamedValue,
    Output,
)

# --------------------------------------------------------------------------- generator


@dataclass(frozen=True)
class Segment:
    """``duration_s`` at ``speed_mps`` turning at ``yaw_rate_dps`` (0 straight; speed 0 parked)."""

    duration_s: float
    speed_mps: float
    yaw_rate_dps: float = 0.0


@dataclass
class TaxiStream:
    samples: list[AttitudeSample | GnssFix]
    turn_windows: list[tuple[float, float]] = field(default_factory=list)
    straight_legs: int = 0


def taxi_stream(
    segments: Sequence[Segment],
    *,
    seed: int,
    heading0_deg: float = 30.0,
    heading_error_deg: float = 1.0,
    vel_noise_mps: float = 0.05,
    vel_acc_mps: float | None = None,
    ins_noise_deg: float = 0.02,
    crab_deg: Callable[[float], float] = lambda t: 0.0,
    vel_bias_ne_mps: tuple[float, float] = (0.0, 0.0),
    att_hz: float = 25.0,
    gnss_hz: float = 10.0,
    gnss_delay_s: float = 0.15,
    alt_m: Callable[[float], float] = lambda t: 120.0,
    pos_noise_m: float = 0.003,
    fix_type: FixType = FixType.FIX_3D,
) -> TaxiStream:
    """Attitude and GNSS samples in arrival order, with the truth's turn windows."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / att_hz
    att: list[AttitudeSample] = []
    fixes: list[GnssFix] = []
    turn_windows: list[tuple[float, float]] = []
    straight = 0
    t = 0.0
    psi = math.radians(heading0_deg)
    gnss_period = 1.0 / gnss_hz
    next_fix_t = 0.0
    err = math.radians(heading_error_deg)
    lat0, lon0 = 0.9, 0.3
    m_m, n_m = radii_of_curvature_m(lat0)
    pos_ne = np.zeros(2)
    for seg in segments:
        rate = math.radians(seg.yaw_rate_dps)
        if rate != 0.0:
            turn_windows.append((t, t + seg.duration_s))
        elif seg.speed_mps > 0.0:
            straight += 1
        t_end = t + seg.duration_s
        while t < t_end - 1e-9:
            yaw_ins = wrap_pi(psi + err + math.radians(ins_noise_deg) * rng.standard_normal())
            att.append(AttitudeSample(t, t, 0.0, 0.0, yaw_ins, np.array([0.0, 0.0, rate])))
            while next_fix_t <= t + 1e-9:
                psi_fix = psi + rate * (next_fix_t - t)
                track = psi_fix + math.radians(crab_deg(next_fix_t))
                vel = seg.speed_mps * np.array([math.cos(track), math.sin(track)])
                vel += np.asarray(vel_bias_ne_mps) + vel_noise_mps * rng.standard_normal(2)
                speed = float(np.hypot(vel[0], vel[1]))
                pos = pos_ne + pos_noise_m * rng.standard_normal(2)
                fixes.append(
                    GnssFix(
                        t_s=next_fix_t,
                        t_rx_s=next_fix_t + gnss_delay_s,
                        receiver_id=0,
                        fix_type=fix_type,
                        lat_rad=lat0 + pos[0] / m_m,
                        lon_rad=lon0 + pos[1] / (n_m * math.cos(lat0)),
                        alt_msl_m=alt_m(next_fix_t),
                        alt_hae_m=None,
                        vel_ne_mps=vel,
                        ground_speed_mps=speed,
                        course_rad=math.atan2(vel[1], vel[0]),
                        h_acc_m=1.0,
                        v_acc_m=2.0,
                        vel_acc_mps=vel_noise_mps if vel_acc_mps is None else vel_acc_mps,
                        hdop=0.8,
                        vdop=1.2,
                        satellites=14,
                    )
                )
                next_fix_t += gnss_period
            # exact arc of the step (constant speed and turn rate)
            if rate != 0.0:
                d_psi = rate * dt
                chord = 2.0 * seg.speed_mps / rate * math.sin(d_psi / 2.0)
                mid = psi + d_psi / 2.0
            else:
                chord = seg.speed_mps * dt
                mid = psi
            pos_ne += chord * np.array([math.cos(mid), math.sin(mid)])
            psi = wrap_pi(psi + rate * dt)
            t += dt
    samples: list[AttitudeSample | GnssFix] = [*att, *fixes]
    samples.sort(key=lambda s: s.t_rx_s)
    return TaxiStream(samples, turn_windows, straight)


def run(corrector: HeadingCorrector, stream: TaxiStream, *, confirm: bool = False) -> list[Output]:
    out: list[Output] = []
    for s in stream.samples:
        if isinstance(s, AttitudeSample):
            corrector.on_attitude(s)
        else:
            got = corrector.on_gnss(s)
            out.extend(got)
            if confirm and any(isinstance(o, Alert) and o.code is AlertCode.HDG_READY for o in got):
                confirm_cmd = HeadingCommand(s.t_s, s.t_rx_s, HeadingAction.CONFIRM)
                out.extend(corrector.on_command(confirm_cmd))
    return out


def alerts(out: list[Output], code: AlertCode) -> list[Alert]:
    return [o for o in out if isinstance(o, Alert) and o.code is code]


PARK = Segment(12.0, 0.0)


def square_taxi(speed: float = 8.0, leg_s: float = 25.0, turn_dps: float = 10.0) -> list[Segment]:
    """Parked stand, then four straight legs joined by 90 degree turns."""
    turn = Segment(90.0 / turn_dps, speed * 0.6, turn_dps)
    return [
        PARK,
        Segment(leg_s, speed),
        turn,
        Segment(leg_s, speed),
        turn,
        Segment(leg_s, speed),
        turn,
        Segment(leg_s, speed),
    ]


def no_park_cfg(**kw: object) -> HeadingConfig:
    return HeadingConfig(require_park_check=False, **kw)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- recursions


def test_running_stats_equal_batch_mean_and_variance() -> None:
    rng = np.random.default_rng(1)
    x = 0.017 + 0.01 * rng.standard_normal(5000)
    s = RunningStats()
    for i, v in enumerate(x, start=1):
        s = s.update(float(v))
        if i in (2, 3, 10, 777, 5000):
            assert s.n == i
            assert s.mean == pytest.approx(np.mean(x[:i]), rel=1e-13, abs=1e-16)
            assert s.var == pytest.approx(np.var(x[:i], ddof=1), rel=1e-11)


def test_corrector_recursions_equal_batch_of_its_cycles() -> None:
    stream = taxi_stream(square_taxi(), seed=2, vel_noise_mps=0.15)
    hc = HeadingCorrector(no_park_cfg(eps_limit_deg=1e-3))  # never sufficient: keeps every cycle
    run(hc, stream)
    x = hc.mismatches_rad()
    est = hc.estimate()
    assert est.n == x.size > 500
    assert est.correction_rad == pytest.approx(np.mean(x), rel=1e-12)
    assert est.sigma_rad == pytest.approx(np.std(x, ddof=1), rel=1e-10)
    assert est.eps_rad == pytest.approx(
        1.959964 * np.std(x, ddof=1) / math.sqrt(x.size - 1), rel=1e-6
    )


# --------------------------------------------------------------------------- estimation


def test_ready_estimate_matches_injected_error_within_its_accuracy() -> None:
    """20 seeded taxis: the 95 % accuracy eps covers the truth in most runs; READY text form."""
    covered = 0
    errors = []
    for seed in range(20):
        stream = taxi_stream(
            square_taxi(), seed=100 + seed, heading_error_deg=1.0, vel_noise_mps=0.1
        )
        hc = HeadingCorrector()
        out = run(hc, stream)
        ready = alerts(out, AlertCode.HDG_READY)
        assert len(ready) == 1, (seed, [o for o in out if isinstance(o, Alert)])
        assert alerts(out, AlertCode.HDG_REJECT) == []
        cand = hc.candidate
        assert cand is not None and hc.phase is HeadingPhase.READY
        assert math.degrees(cand.eps_rad) <= 0.05
        err = math.degrees(cand.correction_rad) - 1.0
        errors.append(err)
        covered += abs(err) <= math.degrees(cand.eps_rad)
        value, pm, n = ready[0].text.split()
        assert float(value) == pytest.approx(math.degrees(cand.correction_rad), abs=0.005)
        assert pm.startswith("±") and n == f"n={cand.n}"
    # binomial(20, 0.95): P(covered < 16) ~ 0.3 %
    assert covered >= 16, errors
    assert max(abs(e) for e in errors) < 0.1


def test_wrap_around_at_180_degrees() -> None:
    """Legs along +-180 deg: INS heading and track straddle the wrap; the mean stays continuous."""
    for err_deg, heading0 in ((1.0, 179.6), (-1.5, -179.7)):
        segs = [
            PARK,
            Segment(60.0, 8.0),
            Segment(6.0, 5.0, 60.0),
            Segment(6.0, 5.0, -60.0),
            Segment(60.0, 8.0),
        ]
        stream = taxi_stream(
            segs, seed=7, heading0_deg=heading0, heading_error_deg=err_deg, vel_noise_mps=0.1
        )
        hc = HeadingCorrector()
        out = run(hc, stream)
        assert alerts(out, AlertCode.HDG_READY), [o for o in out if isinstance(o, Alert)]
        assert hc.candidate is not None
        assert math.degrees(hc.candidate.correction_rad) == pytest.approx(err_deg, abs=0.1)
        # every stored mismatch is near the error, none near +-360
        assert np.all(np.abs(np.degrees(hc.mismatches_rad()) - err_deg) < 5.0)


def test_yaw_interpolation_is_angle_aware() -> None:
    hc = HeadingCorrector()
    a = math.radians(179.8)
    hc.on_attitude(AttitudeSample(0.0, 0.0, 0.0, 0.0, a, np.zeros(3)))
    hc.on_attitude(AttitudeSample(0.1, 0.1, 0.0, 0.0, -a, np.zeros(3)))
    got = hc._attitude.yaw_at(0.05)
    assert got is not None
    assert abs(wrap_pi(got[0] - math.pi)) < 1e-12


def test_turn_ends_leg_and_its_cycles_are_not_used() -> None:
    """During turns the GNSS track is made useless; no cycle inside a turn (or settling) counts."""
    segs = square_taxi(turn_dps=3.0)
    stream = taxi_stream(segs, seed=3, vel_noise_mps=0.1)
    cfg = no_park_cfg(eps_limit_deg=1e-3)
    hc = HeadingCorrector(cfg)
    run(hc, stream)
    t = hc.cycle_times_s()
    for t0, t1 in stream.turn_windows:
        inside = (t >= t0) & (t < t1 + cfg.settle_time_s)
        assert not np.any(inside), (t0, t1, t[inside][:5])
    assert hc.estimate().legs == stream.straight_legs == 4
    assert hc.rejections["turn"] > 0
    # a slow turn just above the limit is still a turn
    slow = taxi_stream(
        [PARK, Segment(30.0, 8.0), Segment(30.0, 8.0, 1.2), Segment(30.0, 8.0)], seed=4
    )
    hc2 = HeadingCorrector(cfg)
    run(hc2, slow)
    t2 = hc2.cycle_times_s()
    assert not np.any((t2 >= 42.0) & (t2 < 72.0))
    assert hc2.estimate().legs == 2


def test_yaw_rate_from_body_rates() -> None:
    roll = math.radians(10.0)
    pitch = math.radians(5.0)
    s = AttitudeSample(0.0, 0.0, roll, pitch, 0.0, np.array([0.0, 0.1, 0.2]))
    expect = (0.1 * math.sin(roll) + 0.2 * math.cos(roll)) / math.cos(pitch)
    assert yaw_rate_radps(s) == pytest.approx(expect, rel=1e-14)


def test_turn_detected_from_heading_change_when_body_rates_are_zero() -> None:
    hc = HeadingCorrector()
    for k in range(50):  # 5 deg/s of heading change with zero reported rates
        t = k * 0.04
        hc.on_attitude(AttitudeSample(t, t, 0.0, 0.0, math.radians(5.0 * t), np.zeros(3)))
    assert any(hc._attitude._turning[15:])


def test_position_track_source_is_accurate_and_fast_with_rtk_positions() -> None:
    """RTK-like positions (3 mm) with a noisy Doppler velocity (0.2 m/s) at 4 m/s.

    The velocity track has 2.9 deg of noise per cycle (no READY in this taxi); the
    1 s displacement has about 0.06 deg, so the position track is READY on the first
    leg, and every position cycle is measured against the truth track.
    """
    segs = [PARK, Segment(40.0, 4.0), Segment(9.0, 3.0, 10.0), Segment(40.0, 4.0)]
    kw = dict(heading_error_deg=-1.3, vel_noise_mps=0.2, fix_type=FixType.RTK_FIXED)
    vel_hc = HeadingCorrector(HeadingConfig(track_source="velocity"))
    assert alerts(run(vel_hc, taxi_stream(segs, seed=40, **kw)), AlertCode.HDG_READY) == []
    # one cycle per second: fewer cycles make a sample than at 10 Hz
    cfg = HeadingConfig(track_source="position", min_cycles=30, spread_start_cycle=10)
    for seed in range(5):
        hc = HeadingCorrector(cfg)
        out = run(hc, taxi_stream(segs, seed=40 + seed, **kw))
        assert alerts(out, AlertCode.HDG_REJECT) == []
        ready = alerts(out, AlertCode.HDG_READY)
        assert ready and hc.candidate is not None
        assert ready[0].t_s < 12.0 + 40.0  # on the first leg
        # cycles: one per second of straight leg (non-overlapping baselines)
        assert np.all(np.diff(hc.cycle_times_s()) >= 1.0 - 1e-6)
        # error within its 95 % accuracy, 2x margin for the 5 draws
        err = hc.candidate.correction_rad - math.radians(-1.3)
        assert abs(err) <= 2.0 * hc.candidate.eps_rad, (seed, math.degrees(err))


def test_auto_source_takes_the_position_track_with_rtk_and_velocity_without() -> None:
    segs = [PARK, Segment(40.0, 4.0), Segment(9.0, 3.0, 10.0), Segment(40.0, 4.0)]
    rtk = HeadingCorrector()  # default: auto
    out = run(
        rtk,
        taxi_stream(
            segs, seed=40, heading_error_deg=-1.3, vel_noise_mps=0.2, fix_type=FixType.RTK_FIXED
        ),
    )
    assert rtk._source == "position" and alerts(out, AlertCode.HDG_READY)
    dgps = HeadingCorrector()
    run(dgps, taxi_stream(segs, seed=40, fix_type=FixType.DGPS))
    assert dgps._source == "velocity" and dgps.estimate().n > 100


def test_auto_source_starts_over_on_the_velocity_track_when_rtk_is_lost() -> None:
    from dataclasses import replace as dc_replace

    stream = taxi_stream([PARK, Segment(40.0, 4.0)], seed=42, fix_type=FixType.RTK_FIXED)
    rtk_lost_at = 12.0 + 20.0  # half way down the leg the corrections drop out
    stream.samples = [
        dc_replace(s, fix_type=FixType.FIX_3D)
        if isinstance(s, GnssFix) and s.t_s >= rtk_lost_at
        else s
        for s in stream.samples
    ]
    hc = HeadingCorrector()
    run(hc, stream)
    assert hc.rejections["track_source_changed"] == 1
    assert hc._source == "velocity"
    # every cycle kept is a velocity cycle after the loss: none of the 1 s position ones
    times = hc.cycle_times_s()
    assert times.size > 50 and times.min() >= rtk_lost_at
    assert np.all(np.diff(times) < 0.5)


def test_position_track_needs_the_fix_type() -> None:
    segs = [PARK, Segment(40.0, 4.0)]
    hc = HeadingCorrector(HeadingConfig(track_source="position"))
    out = run(hc, taxi_stream(segs, seed=41, fix_type=FixType.DGPS))
    assert hc.estimate().n == 0 and alerts(out, AlertCode.HDG_READY) == []
    assert hc.rejections["position_fix_type"] > 0


# --------------------------------------------------------------------------- criteria


def test_changing_crab_angle_is_rejected() -> None:
    """The mismatch drifts by 1.5 deg over 200 s of taxi: never READY, rejected by the trend."""
    for seed in range(3):
        stream = taxi_stream(
            square_taxi(leg_s=45.0),
            seed=20 + seed,
            vel_noise_mps=0.1,
            crab_deg=lambda t: 1.5 * min(max((t - 12.0) / 200.0, 0.0), 1.0),
        )
        hc = HeadingCorrector(HeadingConfig())
        out = run(hc, stream)
        assert alerts(out, AlertCode.HDG_READY) == []
        rej = alerts(out, AlertCode.HDG_REJECT)
        assert rej, seed
        assert rej[0].text.split()[0] in {"trend", "legs_differ", "dispersion", "mean_spread"}


def test_crab_step_between_legs_is_rejected() -> None:
    """A 1 deg crab on the second leg only (a crosswind side): the legs disagree."""

    def crab(t: float) -> float:
        return 1.0 if 60.0 < t < 115.0 else 0.0

    for seed in range(3):
        stream = taxi_stream(
            square_taxi(leg_s=45.0), seed=31 + seed, vel_noise_mps=0.1, crab_deg=crab
        )
        hc = HeadingCorrector()
        out = run(hc, stream)
        assert alerts(out, AlertCode.HDG_READY) == []
        rej = alerts(out, AlertCode.HDG_REJECT)
        assert rej and rej[0].text.split()[0] in {"legs_differ", "trend", "dispersion"}


def test_a_persistent_velocity_bias_tolerated_when_parked_is_caught_in_motion() -> None:
    """0.13 m/s of bias, parked and moving: the parking is only suspect (real receivers show
    that much at standstill), the three legs the suspicion demands show the bias (its
    cross-track part changes sign between opposite legs): rejected, never READY."""
    stream = taxi_stream(square_taxi(), seed=5, vel_noise_mps=0.05, vel_bias_ne_mps=(0.12, -0.05))
    hc = HeadingCorrector()
    out = run(hc, stream)
    assert hc.park_ok is True and hc._park.suspect
    assert alerts(out, AlertCode.HDG_READY) == []
    rej = alerts(out, AlertCode.HDG_REJECT)
    assert rej and rej[0].text.split()[0] in {"legs_differ", "dispersion", "trend"}


def standstill_bias_stream(bias_ne_mps: tuple[float, float], seed: int) -> TaxiStream:
    """The square taxi with a GNSS velocity bias while parked only (as real receivers show)."""
    biased = taxi_stream(square_taxi(), seed=seed, vel_noise_mps=0.05, vel_bias_ne_mps=bias_ne_mps)
    clean = taxi_stream(square_taxi(), seed=seed, vel_noise_mps=0.05)
    samples = [
        b if b.t_s < PARK.duration_s else c
        for b, c in zip(biased.samples, clean.samples, strict=True)
    ]
    return TaxiStream(samples, clean.turn_windows, clean.straight_legs)


@pytest.mark.parametrize("seed", [5, 8])
def test_a_standstill_velocity_bias_raises_no_reject_and_the_correction_is_right(seed) -> None:
    """0.1 m/s at standstill only: no HDG_REJECT; READY with the injected 1 deg inside its 95 %
    uncertainty (truth)."""
    hc = HeadingCorrector()
    out = run(hc, standstill_bias_stream((0.1, 0.0), seed))
    assert alerts(out, AlertCode.HDG_REJECT) == []
    assert alerts(out, AlertCode.HDG_READY) and hc.candidate is not None
    err_deg = math.degrees(hc.candidate.correction_rad) - 1.0
    assert abs(err_deg) <= math.degrees(hc.candidate.eps_rad)


def test_biased_gnss_velocity_is_caught_by_the_legs_without_park_check() -> None:
    """Without the park check a bias needs two headings: min_legs=2 makes the leg test bite.

    Out and back along one taxiway: the cross-track bias flips sign with the heading.
    """
    segs = [Segment(60.0, 8.0), Segment(18.0, 5.0, 10.0), Segment(60.0, 8.0)]
    stream = taxi_stream(segs, seed=6, vel_noise_mps=0.05, vel_bias_ne_mps=(0.12, -0.05))
    hc = HeadingCorrector(no_park_cfg(min_legs=2))
    out = run(hc, stream)
    assert alerts(out, AlertCode.HDG_READY) == []
    rej = alerts(out, AlertCode.HDG_REJECT)
    assert rej and rej[0].text.split()[0] in {"legs_differ", "dispersion", "trend"}
    # the same taxi without the bias passes with min_legs=2
    clean = taxi_stream(segs, seed=6, vel_noise_mps=0.05)
    hc2 = HeadingCorrector(no_park_cfg(min_legs=2))
    out2 = run(hc2, clean)
    assert alerts(out2, AlertCode.HDG_READY) and hc2.candidate is not None
    assert hc2.candidate.legs >= 2


def test_park_verdict_false_alarm_and_detection_rates() -> None:
    """400 unbiased noisy parks (0.2 m/s, 10 s at 10 Hz): at most a few false alarms
    (alpha = 0.001, binomial P(> 3) ~ 0.8 %); a 0.1 m/s bias under 0.05 m/s noise: tolerated
    by the check, always caught as suspect (above ``park_suspect_bias_mps``); 0.3 m/s fails.
    """
    hc = HeadingCorrector()
    cfg = hc.config
    rng = np.random.default_rng(16)
    false = sum(not hc.park_verdict(0.2 * rng.standard_normal((100, 2))).ok for _ in range(400))
    assert false <= 3
    parks = [np.array([0.08, -0.06]) + 0.05 * rng.standard_normal((100, 2)) for _ in range(100)]
    assert all(hc.park_verdict(p).ok for p in parks)
    suspect = sum(
        not park_bias_verdict(p, cfg.park_alpha, cfg.park_suspect_bias_mps).ok for p in parks
    )
    assert suspect == 100
    big = np.array([0.3, 0.0]) + 0.05 * rng.standard_normal((100, 2))
    assert not hc.park_verdict(big).ok


def test_unbiased_park_passes_and_missing_park_blocks_ready() -> None:
    stream = taxi_stream(square_taxi(), seed=8, vel_noise_mps=0.1)
    hc = HeadingCorrector()
    run(hc, stream)
    assert hc.park_ok is True
    no_park = taxi_stream(square_taxi()[1:], seed=8, vel_noise_mps=0.1)
    hc2 = HeadingCorrector()
    out = run(hc2, no_park)
    assert alerts(out, AlertCode.HDG_READY) == []
    assert alerts(out, AlertCode.HDG_REJECT)[0].text == "no_park_check"


def test_underreported_velocity_noise_fails_dispersion() -> None:
    """The receiver claims 0.03 m/s while the noise is 0.2 m/s: the scatter is unexplained."""
    stream = taxi_stream(square_taxi(leg_s=60.0), seed=9, vel_noise_mps=0.2, vel_acc_mps=0.03)
    hc = HeadingCorrector(no_park_cfg(eps_limit_deg=0.1))
    out = run(hc, stream)
    rej = alerts(out, AlertCode.HDG_REJECT)
    assert rej and rej[0].text.startswith("dispersion")


def test_heavy_tailed_mismatch_fails_normality() -> None:
    hc = HeadingCorrector(no_park_cfg())
    rng = np.random.default_rng(10)
    x = 0.02 + 0.005 * rng.standard_t(2, size=2000)
    sample = hc._sample
    sample.x_rad = list(x)
    sample.t_s = list(np.arange(x.size) * 0.1)
    sample.sigma_rad = [0.05] * x.size  # generous: dispersion passes
    sample.leg = [1] * x.size
    for v in x:
        sample.stats = sample.stats.update(float(v))
    verdict = hc.judge()
    assert not verdict.ok and verdict.reason.startswith("not_normal")


# --------------------------------------------------------------------------- ground, apply, publish


def test_not_on_ground_uses_no_cycles() -> None:
    stream = taxi_stream(square_taxi(), seed=11)
    hc = HeadingCorrector(no_park_cfg())
    hc.on_landed_state(False)
    out = run(hc, stream)
    assert hc.estimate().n == 0 and out == []
    # fallback inference: no landed state, but 60 m above the ground reference after 20 s
    hc2 = HeadingCorrector(no_park_cfg(eps_limit_deg=1e-3))
    hc2.on_landed_state(None)
    run(hc2, taxi_stream(square_taxi(), seed=11, alt_m=lambda t: 120.0 + (60.0 if t > 20 else 0)))
    assert hc2.estimate().n > 0
    assert max(hc2.cycle_times_s()) <= 20.0
    assert hc2.rejections["not_on_ground"] > 0


def test_apply_on_confirmation_and_corrected_yaw() -> None:
    stream = taxi_stream(square_taxi(), seed=12, heading_error_deg=-2.0)
    hc = HeadingCorrector()
    assert hc.apply(0.0) == [] and hc.rejections["apply_not_ready"] == 1
    out = run(hc, stream, confirm=True)
    applied = alerts(out, AlertCode.HDG_APPLIED)
    assert len(applied) == 1 and hc.phase is HeadingPhase.APPLIED
    assert math.degrees(hc.correction_rad) == pytest.approx(-2.0, abs=0.1)
    yaw_ins = math.radians(179.5)
    assert hc.corrected_yaw_rad(yaw_ins) == pytest.approx(
        wrap_pi(yaw_ins - hc.correction_rad), abs=1e-15
    )
    assert math.degrees(hc.corrected_yaw_rad(yaw_ins)) == pytest.approx(-178.5, abs=0.1)


def test_auto_apply_and_refusal() -> None:
    stream = taxi_stream(square_taxi(), seed=13)
    hc = HeadingCorrector(HeadingConfig(auto_apply=True))
    out = run(hc, stream)
    assert alerts(out, AlertCode.HDG_READY) and alerts(out, AlertCode.HDG_APPLIED)
    hc2 = HeadingCorrector()
    out2 = run(hc2, taxi_stream(square_taxi()[:3], seed=13))
    assert alerts(out2, AlertCode.HDG_READY)
    got = hc2.on_command(HeadingCommand(200.0, 200.0, HeadingAction.REFUSE))
    assert alerts(got, AlertCode.HDG_REJECT)[0].text == "refused"
    assert hc2.phase is HeadingPhase.ACCUMULATING and hc2.estimate().n == 0
    assert hc2.correction_rad == 0.0


def test_publication_is_throttled_and_carries_estimate() -> None:
    stream = taxi_stream(square_taxi(), seed=14)
    hc = HeadingCorrector(HeadingConfig(publish_period_s=1.0))
    out = run(hc, stream)
    hdgc = [o for o in out if isinstance(o, NamedValue) and o.name == "CMP_HDGC"]
    hdge = [o for o in out if isinstance(o, NamedValue) and o.name == "CMP_HDGE"]
    assert len(hdgc) == len(hdge) > 10
    assert np.all(np.diff([o.t_s for o in hdgc]) >= 1.0 - 1e-9)
    assert abs(hdgc[-1].value - 1.0) < 0.1 and hdge[-1].value <= 0.05


def make_fix(t_s: float, vel: np.ndarray | None, **kw: object) -> GnssFix:
    fields: dict[str, object] = dict(
        t_s=t_s,
        t_rx_s=t_s + 0.1,
        receiver_id=0,
        fix_type=FixType.FIX_3D,
        lat_rad=0.9,
        lon_rad=0.3,
        alt_msl_m=100.0,
        alt_hae_m=None,
        vel_ne_mps=vel,
        ground_speed_mps=5.0,
        course_rad=0.0,
        h_acc_m=1.0,
        v_acc_m=1.0,
        vel_acc_mps=0.1,
        hdop=1.0,
        vdop=1.0,
        satellites=10,
    )
    fields.update(kw)
    return GnssFix(**fields)  # type: ignore[arg-type]


def test_bad_input_is_counted_not_fatal() -> None:
    hc = HeadingCorrector()
    hc.on_attitude(AttitudeSample(0.0, 0.0, 0.0, 0.0, math.nan, np.zeros(3)))
    good = np.array([5.0, 0.0])
    fixes = [
        make_fix(1.0, np.array([math.nan, 1.0])),
        make_fix(1.1, None),
        make_fix(1.2, good, fix_type=FixType.NO_FIX),
        make_fix(1.3, good, vel_acc_mps=3.0),
        make_fix(1.4, good),  # usable, but there is no attitude
        make_fix(1.4, good),  # repeated time of validity
        make_fix(1.5, good, receiver_id=1),
    ]
    for f in fixes:
        assert hc.on_gnss(f) == []
    for reason in (
        "attitude_not_finite",
        "velocity_invalid",
        "no_velocity",
        "fix_type",
        "vel_acc",
        "no_attitude",
        "fix_not_newer",
        "other_receiver",
    ):
        assert hc.rejections[reason] == 1, reason
    assert hc.estimate().n == 0


# --------------------------------------------------------------------------- config, persistence


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("min_speed_mps", 0.0),
        ("max_turn_rate_dps", -1.0),
        ("eps_limit_deg", math.nan),
        ("normality_alpha", 0.7),
        ("confidence", 1.0),
        ("min_cycles", 5),
        ("park_speed_mps", 3.0),
        ("max_speed_mps", 1.0),
        ("ground_crab_deg", 90.0),
        ("park_window_s", 5.0),
        ("spread_start_cycle", 1),
        ("spread_start_cycle", 100),
        ("min_leg_cycles", 2),
        ("attitude_buffer_s", 1.0),
        ("pos_baseline_s", 3.0),
    ],
)
def test_config_validation_names_the_field(name: str, value: object) -> None:
    with pytest.raises(ValueError, match=name):
        HeadingConfig(**{name: value})  # type: ignore[arg-type]


def test_config_accepts_int_fix_types_and_rejects_unknown() -> None:
    assert HeadingConfig(min_fix_type=5).min_fix_type is FixType.RTK_FLOAT  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="pos_min_fix_type"):
        HeadingConfig(pos_min_fix_type=42)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="track_source"):
        HeadingConfig(track_source="compass")


def test_state_round_trip_mid_accumulation_and_applied() -> None:
    stream = taxi_stream(square_taxi(), seed=15)
    half = sum(1 for s in stream.samples if s.t_rx_s < 20.0)  # parked + 8 s of the first leg
    hc = HeadingCorrector()
    full = run(hc, stream)
    # interrupted: stop at a third, persist through JSON, rebuild, continue
    first = HeadingCorrector()
    run(first, TaxiStream(stream.samples[:half]))
    state = json.loads(json.dumps(first.to_state()))
    second = HeadingCorrector.from_state(HeadingConfig(), state)
    assert second.estimate() == first.estimate()
    assert second.park_ok == first.park_ok
    rest = run(second, TaxiStream(stream.samples[half:]))
    assert alerts(rest, AlertCode.HDG_READY) and alerts(full, AlertCode.HDG_READY)
    assert second.candidate is not None and hc.candidate is not None
    # the restart loses only the few seconds of attitude buffer: same estimate to noise level
    assert abs(second.candidate.correction_rad - hc.candidate.correction_rad) < math.radians(0.02)
    # applied survives
    second.apply(300.0)
    third = HeadingCorrector.from_state(HeadingConfig(), json.loads(json.dumps(second.to_state())))
    assert third.phase is HeadingPhase.APPLIED
    assert third.correction_rad == second.correction_rad != 0.0


def test_malformed_state_raises() -> None:
    good = HeadingCorrector().to_state()
    with pytest.raises(ValueError):
        HeadingCorrector.from_state(HeadingConfig(), {**good, "version": 99})
    with pytest.raises(ValueError):
        HeadingCorrector.from_state(
            HeadingConfig(), {k: v for k, v in good.items() if k != "stats"}
        )
    with pytest.raises(ValueError):
        HeadingCorrector.from_state(HeadingConfig(), {**good, "phase": "applied"})
    with pytest.raises(ValueError):
        HeadingCorrector.from_state(HeadingConfig(), {**good, "x_rad": [0.1]})
