"""The receiver's velocity error measured by its own positions
(companion.nav.blend.velocity_error): a persistent bias beyond the reported accuracy is
seen by centimetre positions, never invented from metre-level ones, a change of error
regime or the motion between fixes."""

from __future__ import annotations

import math

import numpy as np

from companion.nav.blend.velocity_error import VelocityErrorMeter
from companion.types import FixType

GAIT_HZ = 1.7
"""A walker's step frequency (the velocity sampled at 5 Hz misses what happens between)."""


def _run(
    seed: int,
    *,
    bias_ne_mps: tuple[float, float] = (0.0, 0.0),
    pos_sigma_m: float = 0.005,
    reported_pos_sigma_m: float = 0.015,
    vel_wobble_mps: float = 0.0,
    jump_at_s: float | None = None,
    duration_s: float = 30.0,
) -> tuple[float, float]:
    """5 Hz fixes of a receiver flying east at 5 m/s (its reported velocity 1-sigma 2 cm/s);
    returns the meter's excess variance, north and east."""
    rng = np.random.default_rng(seed)
    meter = VelocityErrorMeter(0.1)
    excess = (0.0, 0.0)
    offset = np.zeros(2)
    fix_type = FixType.RTK_FIXED
    for k in range(int(duration_s * 5)):
        t = k * 0.2
        if jump_at_s is not None and t >= jump_at_s and fix_type is FixType.RTK_FIXED:
            fix_type, offset = FixType.FIX_3D, np.array([2.0, -1.5])
        # the motion between fixes that the trapezoid rule misses: a gait of GAIT_HZ
        w = 2.0 * math.pi * GAIT_HZ
        truth_pos = np.array([0.0, 5.0 * t + vel_wobble_mps * math.sin(w * t) / w])
        pos = truth_pos + offset + rng.normal(0.0, pos_sigma_m, 2)
        wobble = vel_wobble_mps * math.cos(w * t)
        vel = np.array([0.0, 5.0 + wobble]) + np.array(bias_ne_mps) + rng.normal(0.0, 0.02, 2)
        r_pos = reported_pos_sigma_m**2
        excess = meter.on_fix(
            0, t, (pos[0], pos[1]), (vel[0], vel[1]), (r_pos, r_pos), (4e-4, 4e-4), 30.0, fix_type
        )
    return excess


def test_a_persistent_bias_is_seen_by_centimetre_positions() -> None:
    ex_n, ex_e = _run(1, bias_ne_mps=(0.08, 0.0))
    # fused at 5 Hz, a bias lasting the 10 s window counts as white noise of its variance
    # times 2 T / dt = 100: the velocity no longer drags the position off the fixes
    assert ex_n > 50.0 * 0.08**2, ex_n
    assert ex_e == 0.0


def test_a_velocity_as_good_as_reported_adds_nothing() -> None:
    for seed in range(5):
        assert _run(seed) == (0.0, 0.0)


def test_metre_level_positions_cannot_tell_a_bias() -> None:
    ex = _run(2, bias_ne_mps=(0.08, 0.0), pos_sigma_m=1.0, reported_pos_sigma_m=2.5)
    assert ex == (0.0, 0.0)


def test_a_new_error_regime_is_no_velocity_error() -> None:
    # RTK fixed -> 3D: the position steps by 2.5 m, which no velocity explains
    assert _run(3, jump_at_s=12.0, duration_s=16.0) == (0.0, 0.0)


def test_the_motion_between_fixes_is_not_a_receiver_error() -> None:
    # a velocity swinging +-0.3 m/s with the steps: the trapezoid rule errs from baseline
    # to baseline by up to 0.1 m/s, not persistently
    ex_n, ex_e = _run(4, vel_wobble_mps=0.3, duration_s=60.0)
    assert ex_n == 0.0
    assert ex_e < 0.02**2, ex_e


def test_the_same_fix_offered_twice_keeps_the_chain() -> None:
    # a fix the gate rejected is offered again without the gate (vouched for by the
    # receiver's own evidence): it must not restart the baseline
    meter = VelocityErrorMeter(0.1)
    for k in range(60):
        t = k * 0.2
        for _ in range(2):
            meter.on_fix(0, t, (0.0, 5.0 * t), (0.08, 5.0), (2e-4, 2e-4), (4e-4, 4e-4), 30.0)
    assert meter.excess_var_ne_m2ps2[0] > 50.0 * 0.08**2


def test_a_bias_seen_in_rtk_stands_through_positions_too_coarse_to_see_it() -> None:
    """15 s of RTK fixed with a 0.08 m/s north bias, 20 s of 3-D fixes (1 m position
    noise, 2.5 m reported) with the same velocity, then RTK without the bias: the excess
    measured in RTK stands through the 3-D stretch, whose positions could not have seen
    it (before, it fell to zero within 2 s and the blend drifted metres on the biased
    velocity while claiming decimetres), and it is gone once RTK shows no bias."""
    rng = np.random.default_rng(5)
    meter = VelocityErrorMeter(0.1)
    seen: dict[str, list[float]] = {"rtk": [], "3d": [], "after": []}
    for k in range(60 * 5):
        t = k * 0.2
        phase = "rtk" if t < 15.0 else "3d" if t < 35.0 else "after"
        coarse = phase == "3d"
        pos = np.array([0.0, 5.0 * t]) + rng.normal(0.0, 1.0 if coarse else 0.005, 2)
        bias = 0.0 if phase == "after" else 0.08
        vel = np.array([bias, 5.0]) + rng.normal(0.0, 0.02, 2)
        r_pos = 2.5**2 if coarse else 0.015**2
        fix = FixType.FIX_3D if coarse else FixType.RTK_FIXED
        ex_n, _ = meter.on_fix(
            0, t, (pos[0], pos[1]), (vel[0], vel[1]), (r_pos, r_pos), (4e-4, 4e-4), 30.0, fix
        )
        seen[phase].append(ex_n)
    assert seen["rtk"][-1] > 50.0 * 0.08**2
    assert min(seen["3d"]) > 10.0 * 0.08**2, min(seen["3d"])
    assert seen["after"][-1] == 0.0


def test_a_velocity_seen_at_rest_is_its_error_until_the_positions_judge() -> None:
    """Seeded at rest with the receiver's own velocity (0.12 m/s north at a standstill):
    that is its error from the first fix on; RTK baselines that show a velocity as good
    as reported then clear it."""
    meter = VelocityErrorMeter(0.1)
    assert meter.seed_at_rest(0, (0.12, -0.01), (4e-4, 4e-4))[1] == 0.0  # within its report
    assert meter.excess_var_ne_m2ps2[0] >= 0.12**2
    rng = np.random.default_rng(6)
    excess = meter.excess_var_ne_m2ps2
    for k in range(15 * 5):
        t = k * 0.2
        pos = rng.normal(0.0, 0.005, 2)
        vel = rng.normal(0.0, 0.02, 2)
        excess = meter.on_fix(
            0, t, (pos[0], pos[1]), (vel[0], vel[1]), (2.25e-4, 2.25e-4), (4e-4, 4e-4), 30.0,
            FixType.RTK_FIXED,
        )  # fmt: skip
        if t < 2.0:
            assert excess[0] >= 0.12**2
    assert excess == (0.0, 0.0)
