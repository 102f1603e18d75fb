"""An autopilot that fuses what the service publishes: through a gap the blend carries its
attitude on the autopilot's body rates, not on the autopilot's attitude, which that fusion
corrects with our own output (``EngineConfig.gap_attitude``), and the solution goes to it
as "no fix" once its accuracy passes ``gap_feed_max_h_acc_m``."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from companion.engine import Engine, EngineConfig
from companion.types import AttitudeSample, FixType, HeartbeatSample, NavMode, NavSolution
from tests.helpers import ORIGIN, Line, line_stream

GAP = (10.0, 20.0)
T0 = 10.0
TILT_RAD = math.radians(2.0)


def _tilted_in_gap(stream):
    """The straight flight, with the autopilot's attitude rolled by 2 deg through the gap
    (an autopilot whose attitude follows a drifting input), its body rates untouched."""
    for sample in stream:
        rel = sample.t_s - T0
        if isinstance(sample, AttitudeSample) and GAP[0] + 1.5 <= rel < GAP[1]:
            sample = dataclasses.replace(sample, roll_rad=TILT_RAD)
        yield sample


def _fly(
    engine: Engine, sols: list[NavSolution] | None = None
) -> tuple[float, list[tuple[float, bool]]]:
    """Largest horizontal error over the gap, and (t, attitude held) at each solution."""
    line = Line()
    worst, held = 0.0, []
    for sample in _tilted_in_gap(line_stream(30.0, line=line, gaps=(GAP,))):
        for out in engine.handle(sample):
            if isinstance(out, NavSolution):
                if sols is not None:
                    sols.append(out)
                blend = engine.navigators.primary
                held.append((out.t_s, bool(getattr(blend, "attitude_held", False))))
                if T0 + GAP[0] <= out.t_s < T0 + GAP[1]:
                    err = ORIGIN.lla_to_ned(out.lat_rad, out.lon_rad, out.alt_msl_m)
                    err = err - line.pos_ned_m(out.t_s)
                    worst = max(worst, float(np.hypot(err[0], err[1])))
    return worst, held


def test_fed_autopilot_attitude_is_held_out_through_a_gap() -> None:
    engine = Engine()
    engine.autopilot_fuses_output = True
    sols: list[NavSolution] = []
    worst, held = _fly(engine, sols)
    assert max(s.h_acc_m for s in sols) < 3.0  # fed throughout: never withdrawn
    assert all(s.fix_type >= FixType.FIX_3D for s in sols if s.t_s > T0 + 1.0)
    # the rates (zero) carry the level attitude: centimetres, as without the tilt
    assert worst < 0.1
    in_gap = [h for t, h in held if T0 + GAP[0] + 1.5 <= t < T0 + GAP[1]]
    assert in_gap and all(in_gap)
    assert not any(h for t, h in held if t >= T0 + GAP[1] + 1.0)  # taken again after
    assert not any(h for t, h in held if t < T0 + GAP[0])


def test_attitude_taken_when_the_autopilot_does_not_fuse_us() -> None:
    worst, held = _fly(Engine())
    # the 2 deg roll is taken: g * sin(2 deg) = 0.34 m/s^2 sideways for up to 8.5 s
    assert worst > 5.0
    assert not any(h for _, h in held)


def test_gap_attitude_settings() -> None:
    forced = Engine(EngineConfig(gap_attitude="rates"))
    worst, _ = _fly(forced)
    assert worst < 0.1
    never = Engine(EngineConfig(gap_attitude="autopilot"))
    never.autopilot_fuses_output = True
    worst, held = _fly(never)
    assert worst > 5.0
    assert not any(h for _, h in held)


def test_fix_withdrawn_past_the_accuracy_limit() -> None:
    """Once the bridge's accuracy passes ``gap_feed_max_h_acc_m`` the autopilot gets "no
    fix" for the rest of the gap; its attitude stays held out (what it fused stays in it)."""
    engine = Engine(EngineConfig(gap_feed_max_h_acc_m=0.05))
    engine.autopilot_fuses_output = True
    sols: list[NavSolution] = []
    _, held = _fly(engine, sols)
    gap = [s for s in sols if T0 + GAP[0] + 1.5 <= s.t_s < T0 + GAP[1]]
    first_out = next(s for s in gap if s.h_acc_m > 0.05)
    assert first_out.fix_type is FixType.NO_FIX
    assert all(s.fix_type is FixType.NO_FIX for s in gap if s.t_s >= first_out.t_s)
    assert all(s.fix_type is FixType.FIX_3D for s in gap if s.t_s < first_out.t_s)
    assert all(h for t, h in held if T0 + GAP[0] + 1.5 <= t < T0 + GAP[1])
    after = [s for s in sols if s.t_s > T0 + GAP[1] and s.mode is NavMode.NORMAL]
    assert after and all(s.fix_type is FixType.RTK_FIXED for s in after)
    assert engine.stats.gnss["gap_feed_withdrawn"] == 1


def _multirotor(engine: Engine) -> Engine:
    """The engine told by the autopilot's HEARTBEAT that it flies a quadrotor."""
    engine.handle(HeartbeatSample(0.0, 0.0, 1, 3, 2, True, 4))
    return engine


def test_a_multirotor_is_fed_through_the_whole_gap() -> None:
    """A multirotor's filter cannot dead-reckon without a position source (ArduCopter:
    EKF failsafe, then its position held still): it is fed through the gap whatever the
    fixed wing's limit (``gap_feed_no_airspeed_max_h_acc_m``, inf by default)."""
    engine = _multirotor(Engine(EngineConfig(gap_feed_max_h_acc_m=0.05)))
    engine.autopilot_fuses_output = True
    sols: list[NavSolution] = []
    _fly(engine, sols)
    gap = [s for s in sols if T0 + GAP[0] + 1.5 <= s.t_s < T0 + GAP[1]]
    assert gap and max(s.h_acc_m for s in gap) > 0.05
    assert all(s.fix_type >= FixType.FIX_3D for s in gap)
    assert engine.stats.gnss["gap_feed_withdrawn"] == 0


def test_a_multirotor_has_its_own_limit() -> None:
    engine = _multirotor(Engine(EngineConfig(gap_feed_no_airspeed_max_h_acc_m=0.05)))
    engine.autopilot_fuses_output = True
    sols: list[NavSolution] = []
    _fly(engine, sols)
    gap = [s for s in sols if T0 + GAP[0] + 1.5 <= s.t_s < T0 + GAP[1]]
    assert any(s.fix_type is FixType.NO_FIX for s in gap)
    assert engine.stats.gnss["gap_feed_withdrawn"] == 1
