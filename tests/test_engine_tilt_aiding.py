"""Whether the autopilot's tilt is still levelled without GNSS (:mod:`companion.engine.
tilt_aiding`): its airframe and its own position held still, and the engine modelling the
tilt unaided through a gap it shares only then."""

from __future__ import annotations

import math

import numpy as np

from companion.engine import Engine
from companion.engine.tilt_aiding import HOLD_S, TiltAiding
from companion.nav.blend import BlendNavigator
from companion.types import AutopilotSolution, HeartbeatSample, NavSolution
from tests.helpers import Line, line_stream

GAP = (10.0, 20.0)
T0 = 10.0
LAT, LON = math.radians(-35.36), math.radians(149.16)


def test_a_position_held_to_the_last_bit_for_a_second_is_held() -> None:
    aiding = TiltAiding()
    assert not aiding.lost
    for k in range(20):  # a real solution: moves by a bit every time
        assert not aiding.on_solution(0.2 * k, LAT + (k + 1) * 1e-9, LON)
    t = 4.0
    for k in range(5):  # the same position for 0.8 s: not yet
        assert not aiding.on_solution(t + 0.2 * k, LAT, LON)
    t += HOLD_S
    assert aiding.on_solution(t, LAT, LON)
    assert aiding.held and aiding.lost and aiding.held_episodes == 1
    assert aiding.on_solution(t + 0.4, LAT, LON)  # still held: one episode
    assert aiding.held_episodes == 1
    assert not aiding.on_solution(t + 0.6, LAT, LON + 1e-9)  # it moves: released
    assert not aiding.lost
    assert not aiding.on_solution(math.nan, LAT, LON)  # not finite: ignored
    assert not aiding.on_solution(t + 0.8, math.inf, LON)


def test_a_multirotor_has_nothing_but_gnss_to_level_its_tilt() -> None:
    aiding = TiltAiding()
    aiding.on_heartbeat(2)  # MAV_TYPE_QUADROTOR
    assert aiding.lost
    aiding.on_heartbeat(1)  # MAV_TYPE_FIXED_WING: its airspeed
    assert not aiding.lost
    aiding.on_heartbeat(13)  # HEXAROTOR
    assert aiding.no_airspeed


def _fly(vehicle_type: int) -> tuple[list[bool], float]:
    """The straight flight with a 10 s gap beside an autopilot of ``vehicle_type``: the
    blend's tilt-unaided flag through the gap, and the largest published accuracy in it."""
    engine = Engine()
    beat = HeartbeatSample(0.0, 0.0, 1, 3, vehicle_type, True, 4)
    flags, h_acc = [], 0.0
    for sample in line_stream(30.0, line=Line(), gaps=(GAP,)):
        engine.handle(beat)
        for out in engine.handle(sample):
            if isinstance(out, NavSolution) and T0 + GAP[0] + 1.5 <= out.t_s < T0 + GAP[1]:
                blend = engine.navigators.primary
                assert isinstance(blend, BlendNavigator)
                flags.append(blend.tilt_unaided_flag)
                h_acc = max(h_acc, out.h_acc_m)
    return flags, h_acc


def test_engine_models_the_tilt_unaided_beside_a_multirotor_only() -> None:
    quad, quad_h = _fly(2)
    plane, plane_h = _fly(1)
    assert quad and all(quad)
    assert plane and not any(plane)
    assert quad_h > plane_h  # the tilt's error now grows as a strapdown's


def test_engine_follows_the_autopilots_held_position() -> None:
    engine = Engine()
    for k in range(10):
        engine.handle(AutopilotSolution(0.2 * k, 0.2 * k, LAT, LON, 100.0, np.zeros(3), None))
    assert engine.tilt_aiding.held
    engine.handle(AutopilotSolution(2.2, 2.2, LAT + 1e-9, LON, 100.0, np.zeros(3), None))
    assert not engine.tilt_aiding.held
