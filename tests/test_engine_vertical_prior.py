"""The engine's vertical prior through a GNSS gap (companion.nav.vertical_prior), on
synthetic level flights with known truth: an accelerometer error in the gap is bounded
by the recent heights; a descent begun in the gap is followed by the INS."""

from __future__ import annotations

import dataclasses

import numpy as np

from companion.engine import Engine, EngineConfig
from companion.types import ImuSample, NavMode, NavSolution
from tests.helpers import ORIGIN, Line, line_stream

T0_S = 10.0
GAP_S = (20.0, 25.0)
"""A 5 s GNSS gap, seconds after the stream's start (20 s of fixes before it)."""
LEVEL = Line(vel_ned_mps=(40.0, 30.0, 0.0))


def gap_solutions(stream, vertical_prior: bool) -> list[NavSolution]:
    engine = Engine(EngineConfig(vertical_prior=vertical_prior))
    outs = []
    for sample in stream:
        outs += engine.handle(sample)
    return [o for o in outs if isinstance(o, NavSolution) and o.mode is NavMode.BRIDGING]


def with_accel_down(stream, accel_down) -> list:
    """The stream with ``accel_down(t_rel)`` m/s^2 added to the vertical specific force."""
    out = []
    for s in stream:
        if isinstance(s, ImuSample):
            a = accel_down(s.t_s - T0_S)
            if a:
                s = dataclasses.replace(s, acc_b_mps2=s.acc_b_mps2 + np.array([0.0, 0.0, a]))
        out.append(s)
    return out


def down_error_m(sol: NavSolution, truth_d_m: float) -> float:
    return float(ORIGIN.lla_to_ned(sol.lat_rad, sol.lon_rad, sol.alt_msl_m)[2] - truth_d_m)


def test_an_accelerometer_error_in_the_gap_is_bounded_by_the_recent_heights() -> None:
    base = list(line_stream(GAP_S[1], line=LEVEL, gaps=(GAP_S,), noise_m=0.02, seed=5))
    # 0.02 m/s^2 of vertical specific-force error from the gap's start (twice the
    # configured accelerometer bias sigma): 0.25 m in 5 s
    stream = with_accel_down(base, lambda t: 0.02 if t >= GAP_S[0] else 0.0)
    ins = gap_solutions(stream, False)
    both = gap_solutions(stream, True)
    assert len(ins) == len(both) >= 30
    e_ins = abs(down_error_m(ins[-1], 0.0))
    e_both = abs(down_error_m(both[-1], 0.0))
    assert e_ins > 0.12  # the INS alone drifts
    assert e_both < 0.5 * e_ins
    for a, b in zip(ins, both, strict=True):  # no less certain than it is wrong
        assert abs(down_error_m(b, 0.0)) <= 2.0 * b.v_acc_m
        assert b.v_acc_m <= a.v_acc_m + 1e-9


def test_an_ins_far_beyond_its_bound_is_believed_alone() -> None:
    """0.3 m/s^2 (30 sigma of the configured bias) looks like a manoeuvre, not an error:
    the prediction is withdrawn and the INS carries the height alone."""
    base = list(line_stream(GAP_S[1], line=LEVEL, gaps=(GAP_S,), noise_m=0.02, seed=5))
    stream = with_accel_down(base, lambda t: 0.3 if t >= GAP_S[0] else 0.0)
    ins = gap_solutions(stream, False)
    both = gap_solutions(stream, True)
    assert abs(down_error_m(ins[-1], 0.0) - down_error_m(both[-1], 0.0)) < 1e-3


def test_a_descent_begun_in_the_gap_is_the_ins_s() -> None:
    base = list(line_stream(GAP_S[1], line=LEVEL, gaps=(GAP_S,), noise_m=0.02, seed=6))
    # 2 m/s^2 down for 1.5 s from the gap's start, then 3 m/s of descent
    a0, dur = GAP_S[0], 1.5
    stream = with_accel_down(base, lambda t: 2.0 if a0 <= t < a0 + dur else 0.0)

    def truth_d(t_rel: float) -> float:
        x = t_rel - a0
        if x <= 0.0:
            return 0.0
        if x <= dur:
            return 0.5 * 2.0 * x * x
        return 0.5 * 2.0 * dur * dur + 2.0 * dur * (x - dur)

    ins = gap_solutions(stream, False)
    both = gap_solutions(stream, True)
    last_ins, last_both = ins[-1], both[-1]
    truth = truth_d(last_both.t_s - T0_S)
    assert truth > 8.0
    # the prediction of no change is withdrawn: the published height is the INS's
    assert abs(down_error_m(last_both, truth) - down_error_m(last_ins, truth)) < 0.05
    assert abs(down_error_m(last_both, truth)) < 0.5
