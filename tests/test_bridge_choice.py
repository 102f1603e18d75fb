"""The gap's motion model chosen on the flight's own evidence: an autopilot attitude that
disagrees with the accelerometer (as on real ArduPilot logs: degrees of tilt at rest)
makes the inertial bridge err far beyond its model, and constant velocity carries the gap;
a consistent one keeps the inertial bridge."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.engine import Engine
from companion.engine.bridge_choice import BridgeEvidence, inertial_accel_sigma_mps2
from companion.nav.blend import BlendConfig
from companion.types import Alert, AlertCode, AttitudeSample, FixType, GnssFix, NavSolution
from tests.helpers import ORIGIN, Line, line_stream

GAP = (40.0, 47.0)
"""A 7 s GNSS gap, relative to the stream's start (as in the real loiter flight)."""


WANDER_PERIOD_S = 20.0
"""Period of the autopilot attitude's wandering error (faster than any bias state follows)."""


def tilted(stream, roll_rad):
    """The stream with the autopilot's roll wandering by ``roll_rad`` (amplitude, a sine of
    :data:`WANDER_PERIOD_S`) while the IMU reads level, and a 3-D receiver reporting 1 m
    (as the autopilot logs' receivers)."""
    for s in stream:
        if isinstance(s, AttitudeSample):
            wander = roll_rad * math.sin(2.0 * math.pi * s.t_s / WANDER_PERIOD_S)
            s = dataclasses.replace(s, roll_rad=s.roll_rad + wander)
        elif isinstance(s, GnssFix):
            s = dataclasses.replace(
                s, fix_type=FixType.FIX_3D, h_acc_m=2.5, v_acc_m=4.0, vel_acc_mps=0.3
            )
        yield s


def fly(roll_deg: float, choose: bool = True):
    """The flight with the attitude wandering by ``roll_deg``; ``choose=False``: the gap is
    bridged inertially whatever the evidence (what the choice is measured against)."""
    line = Line(vel_ned_mps=(8.0, 3.0, 0.0))
    engine = Engine()
    if not choose:
        engine.bridge_evidence.constant_velocity_better = lambda: False  # type: ignore[method-assign]
    outs = []
    stream = line_stream(60.0, line=line, gnss_hz=5.0, gaps=(GAP,), noise_m=0.3, seed=4)
    for sample in tilted(stream, math.radians(roll_deg)):
        outs += engine.handle(sample)
    lost = [o for o in outs if isinstance(o, Alert) and o.code is AlertCode.GNSS_LOST]
    t_end = 10.0 + GAP[1]
    last = [o for o in outs if isinstance(o, NavSolution) and o.t_s < t_end][-1]
    err = ORIGIN.lla_to_ned(last.lat_rad, last.lon_rad, last.alt_msl_m) - line.pos_ned_m(last.t_s)
    return engine, lost, float(np.hypot(err[0], err[1])), last


def test_attitude_disagreeing_with_the_imu_hands_the_gap_to_constant_velocity():
    _, _, inertial_closure_m, _ = fly(4.0, choose=False)
    engine, lost, closure_m, last = fly(4.0)
    ev = engine.bridge_evidence
    assert len(ev.results) >= ev.min_probes
    assert ev.constant_velocity_better()
    assert len(lost) == 1 and lost[0].text.endswith("bridging on velocity")
    # the line is straight: constant velocity closes at the fixes' noise, and the
    # published accuracy (growing with the pass-through's model) covers it
    assert closure_m < 1.0 and inertial_closure_m > 5.0 * closure_m
    sigma_h = math.sqrt(max(last.pos_cov_ned_m2[0, 0], last.pos_cov_ned_m2[1, 1]))
    assert closure_m < 3.0 * sigma_h
    assert engine.stats.gnss["gap_bridged_cv"] == 1


def test_a_consistent_imu_keeps_the_inertial_bridge():
    engine, lost, closure_m, _ = fly(0.0)
    assert not engine.bridge_evidence.constant_velocity_better()
    assert len(lost) == 1 and lost[0].text.endswith(": bridging")
    assert closure_m < 1.0
    assert engine.stats.gnss["gap_bridged_cv"] == 0


def test_the_grade_bound_is_the_99_percent_radius_of_twice_integrated_error():
    sigma = inertial_accel_sigma_mps2(BlendConfig.for_grade("mems"))
    ev = BridgeEvidence(sigma)
    # sqrt(chi2.ppf(0.99, 2)) = sqrt(-2 ln 0.01)
    assert ev.grade_bound_m(5.0) == pytest.approx(
        math.sqrt(-2.0 * math.log(0.01)) * 0.5 * sigma * 25.0
    )
    with pytest.raises(ValueError):
        BridgeEvidence(0.0)
    assert not ev.constant_velocity_better()  # no evidence: the inertial bridge
