"""A receiver judged by its own evidence: quality, position increments against its velocity."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from companion.nav.receiver_checks import ReceiverCheckConfig, ReceiverConsistency
from companion.types import FixType
from tests.helpers import Line, fix_at

CFG = ReceiverCheckConfig()
LINE = Line((30.0, 10.0, 0.0))
VEL = np.array(LINE.vel_ned_mps)


def healthy(t, offset=(0.0, 0.0, 0.0), **kw):
    """A 3D fix on the line (5 Hz receiver, 10 satellites, HDOP 1.2)."""
    f = fix_at(t, LINE.pos_ned_m(t, 0.0) + np.array(offset), VEL, fix_type=FixType.FIX_3D, **kw)
    return replace(f, satellites=10, hdop=1.2)


def feed(checks, fixes):
    return [checks.on_fix(f, CFG) for f in fixes]


def test_a_healthy_moving_receiver_is_self_consistent_after_the_window():
    checks = ReceiverConsistency()
    times = [k * 0.2 for k in range(15)]
    assert feed(checks, [healthy(t) for t in times]) == [""] * 15
    assert not checks.consistent(1.0, CFG)  # the chain spans 1 s: not yet
    assert checks.consistent(2.8, CFG)


def test_a_glitch_breaks_the_chain_and_it_restarts_at_the_step():
    checks = ReceiverConsistency()
    feed(checks, [healthy(k * 0.2) for k in range(15)])
    assert checks.consistent(2.8, CFG)
    why = checks.on_fix(healthy(3.0, offset=(20.0, 0.0, 0.0)), CFG)
    assert why.startswith("moved") and not checks.consistent(3.0, CFG)
    # the step persists: consistent with itself again after the window
    feed(checks, [healthy(3.0 + k * 0.2, offset=(20.0, 0.0, 0.0)) for k in range(1, 11)])
    assert checks.chain_start_t_s == 3.0 and checks.consistent(5.0, CFG)


def test_a_frozen_receiver_whose_velocity_says_moving_is_never_consistent():
    checks = ReceiverConsistency()
    feed(checks, [healthy(k * 0.2) for k in range(5)])
    frozen = healthy(0.8)
    whys = feed(checks, [replace(frozen, t_s=1.0 + k * 0.2) for k in range(20)])
    assert all(whys)  # every increment fails: 6 m expected each, 0 moved
    assert not checks.consistent(5.0, CFG)


def test_the_same_time_stamp_again_is_a_repeat_not_evidence():
    checks = ReceiverConsistency()
    feed(checks, [healthy(k * 0.2) for k in range(5)])
    assert checks.on_fix(healthy(0.8), CFG) == "repeat"
    assert checks.chain_fixes == 5


def test_quality_failures_end_the_chain():
    checks = ReceiverConsistency()
    feed(checks, [healthy(k * 0.2) for k in range(15)])
    assert checks.on_fix(replace(healthy(3.0), satellites=4), CFG) == "4 satellites"
    assert checks.chain_start_t_s is None and not checks.consistent(3.0, CFG)
    assert checks.on_fix(replace(healthy(3.2), hdop=6.0), CFG) == "HDOP 6.0"
    assert checks.on_fix(replace(healthy(3.4), fix_type=FixType.FIX_2D), CFG) == "fix type 2"
    assert checks.on_fix(healthy(3.6), CFG) == ""
    assert checks.chain_start_t_s == 3.6


def test_a_slow_ramp_the_velocity_does_not_show_breaks_the_chain():
    """1 m/s of position drift, 0.2 m per fix (inside the increment tolerance), shows in
    the chain's integrated residual within 4 m + 0.5 m/s x T: in under 10 s."""
    checks = ReceiverConsistency()
    whys = feed(checks, [healthy(k * 0.2, offset=(1.0 * k * 0.2, 0.0, 0.0)) for k in range(60)])
    broken = [k * 0.2 for k, w in enumerate(whys) if w]
    assert broken and broken[0] < 10.0
    assert whys[int(broken[0] / 0.2)].startswith("drifted")


def test_a_gap_restarts_the_chain_without_a_failure():
    checks = ReceiverConsistency()
    feed(checks, [healthy(k * 0.2) for k in range(15)])
    assert checks.on_fix(healthy(10.0, offset=(300.0, 0.0, 0.0)), CFG) == ""
    assert checks.chain_start_t_s == 10.0 and checks.last_failure == ""
