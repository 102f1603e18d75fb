"""The ground/air decision of the taxi heading correction against simulated truth.

An ArduPlane-like autopilot says "in air" as soon as the aircraft rolls: the taxi
must still count, a real take-off (climb) must end it, and after landing the taxi
must count again, whether or not the autopilot ever says "on ground" again.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from companion.engine import Engine
from companion.nav.earth import radii_of_curvature_m
from companion.nav.heading import HeadingConfig, HeadingCorrector
from companion.nav.rotations import wrap_pi
from companion.types import (
    AttitudeSample,
    FixType,
    GnssFix,
    LandedState,
    LandedStateSample,
    Sample,
    VfrHudSample,
)

HEADING_ERROR_DEG = 1.0
REF_ALT_M = 120.0


@dataclass(frozen=True)
class Truth:
    """The truth at a time: ground speed, climb, height above the runway, pitch, yaw
    rate and the ArduPlane-like landed state."""

    speed_mps: float
    climb_mps: float
    height_m: float
    pitch_deg: float
    yaw_rate_dps: float
    landed: LandedState


def flight(t: float, *, says_on_ground_after_landing: bool) -> Truth:
    """Parked 15 s (on ground), taxi at 4-7 m/s with one 90 deg turn ("in air" while
    rolling), take-off run, climb to 90 m, cruise, descent, touchdown at 250 s,
    roll-out to 265 s; then parked 10 s and taxi again, or (the autopilot never says
    "on ground") taxi on at once."""
    air, ground = LandedState.IN_AIR, LandedState.ON_GROUND
    if t < 15.0:
        return Truth(0.0, 0.0, 0.0, 1.0, 0.0, ground)
    if t < 85.0:  # taxi: speed between 4 and 7 m/s, a turn at 45-54 s
        rate = 10.0 if 45.0 <= t < 54.0 else 0.0
        return Truth(5.5 + 1.5 * math.sin(0.3 * t), 0.0, 0.0, 1.0, rate, air)
    if t < 100.0:  # take-off run 5 -> 25 m/s
        return Truth(5.0 + 20.0 * (t - 85.0) / 15.0, 0.0, 0.0, 1.0, 0.0, air)
    if t < 130.0:  # climb
        return Truth(25.0, 3.0, 3.0 * (t - 100.0), 8.0, 0.0, air)
    if t < 220.0:  # cruise
        return Truth(25.0, 0.0, 90.0, 2.0, 0.0, air)
    if t < 250.0:  # descent
        return Truth(22.0, -3.0, 90.0 - 3.0 * (t - 220.0), -2.0, 0.0, air)
    if t < 265.0:  # roll-out 22 -> 5 m/s, still "in air" (ArduPlane: above 5 m/s)
        return Truth(22.0 - 17.0 * (t - 250.0) / 15.0, 0.0, 0.0, 1.0, 0.0, air)
    if says_on_ground_after_landing and t < 275.0:
        return Truth(0.0, 0.0, 0.0, 1.0, 0.0, ground)
    return Truth(5.0 + 1.0 * math.sin(0.3 * t), 0.0, 0.0, 1.0, 0.0, air)


def samples(
    truth: Callable[[float], Truth], t_end_s: float, *, seed: int, with_landed: bool = True
) -> list[Sample]:
    """ATTITUDE at 25 Hz (heading off by ``HEADING_ERROR_DEG``), GNSS at 10 Hz,
    VFR_HUD at 4 Hz, EXTENDED_SYS_STATE at 1 Hz, in time order."""
    rng = np.random.default_rng(seed)
    lat0, lon0 = 0.9, 0.3
    m_m, n_m = radii_of_curvature_m(lat0)
    pos = np.zeros(2)
    psi = math.radians(30.0)
    out: list[Sample] = []
    dt = 0.04
    for k in range(int(t_end_s / dt)):
        t = k * dt
        tr = truth(t)
        rate = math.radians(tr.yaw_rate_dps)
        yaw_ins = wrap_pi(psi + math.radians(HEADING_ERROR_DEG) + 3e-4 * rng.standard_normal())
        pitch = math.radians(tr.pitch_deg)
        out.append(AttitudeSample(t, t, 0.0, pitch, yaw_ins, np.array([0.0, 0.0, rate])))
        if k % 10 == 0:
            out.append(VfrHudSample(t, t, tr.speed_mps, tr.speed_mps, psi, 0.0, tr.climb_mps))
        if with_landed and k % 25 == 0:
            out.append(LandedStateSample(t, t, tr.landed))
        if k % 4 == 0:
            vel = tr.speed_mps * np.array([math.cos(psi), math.sin(psi)])
            vel += 0.05 * rng.standard_normal(2)
            out.append(
                GnssFix(
                    t_s=t,
                    t_rx_s=t,
                    receiver_id=0,
                    fix_type=FixType.FIX_3D,
                    lat_rad=lat0 + pos[0] / m_m,
                    lon_rad=lon0 + pos[1] / (n_m * math.cos(lat0)),
                    alt_msl_m=REF_ALT_M + tr.height_m + 0.5 * rng.standard_normal(),
                    alt_hae_m=None,
                    vel_ne_mps=vel,
                    ground_speed_mps=float(np.hypot(vel[0], vel[1])),
                    course_rad=math.atan2(vel[1], vel[0]),
                    h_acc_m=1.0,
                    v_acc_m=2.0,
                    vel_acc_mps=0.05,
                    hdop=0.8,
                    vdop=1.2,
                    satellites=14,
                )
            )
        pos += tr.speed_mps * dt * np.array([math.cos(psi), math.sin(psi)])
        psi = wrap_pi(psi + rate * dt)
    return out


def never_ready(**kw: float) -> HeadingConfig:
    """No park check, and an accuracy goal never met: the cycles only accumulate."""
    return HeadingConfig(require_park_check=False, eps_limit_deg=1e-3, **kw)  # type: ignore[arg-type]


def run_engine(
    stream: list[Sample], cfg: HeadingConfig | None = None
) -> tuple[Engine, list[tuple[float, bool, int]]]:
    """The engine over the stream; per fix: time, airborne, cycles accumulated."""
    engine = Engine(heading=cfg or never_ready())
    trace: list[tuple[float, bool, int]] = []
    for s in stream:
        engine.handle(s)
        if isinstance(s, GnssFix):
            trace.append((s.t_s, engine.heading.airborne, engine.heading.estimate().n))
    return engine, trace


def test_arduplane_taxi_in_air_counts_take_off_ends_it_landing_resumes_it() -> None:
    stream = samples(lambda t: flight(t, says_on_ground_after_landing=True), 340.0, seed=19)
    # a release by the motion alone later than the autopilot's "on ground" (265 s)
    engine, trace = run_engine(stream, never_ready(ground_release_s=60.0))
    taxi = [row for row in trace if 15.0 <= row[0] < 85.0]
    # the taxi counted although the autopilot said "in air" while rolling
    assert not any(airborne for _, airborne, _ in taxi)
    n_taxi = taxi[-1][2]
    assert n_taxi > 300
    # take-off: airborne from the climb (or the speed beyond a taxi) on, all flight long
    first_air = next(t for t, airborne, _ in trace if airborne)
    assert 90.0 < first_air <= 100.5
    # landing: the autopilot's "on ground" ends the flight; the taxi after it counts anew
    assert all(airborne for t, airborne, _ in trace if 100.5 <= t < 265.0)
    assert not any(airborne for t, airborne, _ in trace if t >= 265.5)
    assert trace[-1][2] > 300
    times = engine.heading.cycle_times_s()
    assert times.min() >= 250.0
    mean_deg = math.degrees(engine.heading.estimate().correction_rad)
    assert abs(mean_deg - HEADING_ERROR_DEG) < 0.1


def test_taxi_resumes_after_landing_when_the_autopilot_never_says_on_ground() -> None:
    cfg = never_ready()
    stream = samples(lambda t: flight(t, says_on_ground_after_landing=False), 330.0, seed=20)
    _, trace = run_engine(stream)
    assert all(airborne for t, airborne, _ in trace if 100.5 <= t < 250.0)
    back = next(t for t, airborne, _ in trace if t > 250.0 and not airborne)
    # the roll-out slows below the taxi limit at ~251.8 s; then the release time
    assert 251.0 + cfg.ground_release_s < back < 253.0 + cfg.ground_release_s
    assert not any(airborne for t, airborne, _ in trace if t >= back)
    assert trace[-1][2] > 300


def test_a_low_hover_is_not_a_taxi() -> None:
    """A vehicle climbing to 10 m and moving at taxi speeds there stays in the air
    (beyond the release height), though its speed, climb and pitch look like a taxi."""

    def hover(t: float) -> Truth:
        if t < 10.0:
            return Truth(0.0, 0.0, 0.0, 0.0, 0.0, LandedState.ON_GROUND)
        if t < 15.0:
            return Truth(0.0, 2.0, 2.0 * (t - 10.0), 0.0, 0.0, LandedState.IN_AIR)
        return Truth(5.0, 0.0, 10.0, 2.0, 0.0, LandedState.IN_AIR)

    _, trace = run_engine(samples(hover, 120.0, seed=21))
    assert all(airborne for t, airborne, _ in trace if t >= 12.0)
    assert trace[-1][2] == 0


def test_in_air_with_no_ground_reference_is_a_flight() -> None:
    """The service starts in the air (no fix on the ground yet): the autopilot's
    "in air" is taken, even slow and level."""
    hc = HeadingCorrector(never_ready())
    hc.on_landed_state(False)
    slow = samples(lambda t: Truth(6.0, 0.0, 40.0, 0.0, 0.0, LandedState.IN_AIR), 20.0, seed=22)
    for s in slow:
        if isinstance(s, GnssFix):
            hc.observe_fix(s)
            hc.on_gnss(s)
    assert hc.airborne and hc.estimate().n == 0


def test_without_a_landed_state_the_motion_decides_fix_by_fix() -> None:
    """No EXTENDED_SYS_STATE: no flight is latched; the taxi counts, the flight does not."""
    stream = samples(
        lambda t: flight(t, says_on_ground_after_landing=True), 200.0, seed=23, with_landed=False
    )
    engine, trace = run_engine(stream)
    assert not any(airborne for _, airborne, _ in trace)
    assert engine.heading.rejections["not_on_ground"] > 0
    times = engine.heading.cycle_times_s()
    assert times.size > 300 and times.max() < 100.5
