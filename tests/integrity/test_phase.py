"""Flight phase from the state."""

from __future__ import annotations

import numpy as np
import pytest

from companion.integrity.protection.limits import FlightPhase
from companion.integrity.protection.phase import PhaseClassifier, PhaseConfig
from companion.types import LandedState

FIELD = 110.0


def v(n: float, d: float) -> np.ndarray:
    return np.array([n, 0.0, d])


def test_a_whole_flight_without_landed_state() -> None:
    pc = PhaseClassifier(PhaseConfig(field_elevation_msl_m=FIELD))
    seq = [
        (FIELD, v(0.0, 0.0), FlightPhase.TAXI),
        (FIELD, v(8.0, 0.0), FlightPhase.TAXI),
        (FIELD, v(30.0, 0.0), FlightPhase.TAKEOFF),  # take-off roll
        (FIELD + 100.0, v(50.0, -5.0), FlightPhase.TAKEOFF),  # departure climb
        (FIELD + 1000.0, v(60.0, 0.0), FlightPhase.ENROUTE),
        (FIELD + 300.0, v(60.0, 3.0), FlightPhase.APPROACH),
        (FIELD + 200.0, v(60.0, 0.0), FlightPhase.APPROACH),  # level segment: stays
        (FIELD + 20.0, v(60.0, 3.0), FlightPhase.LANDING),
        (FIELD + 2.0, v(55.0, 0.5), FlightPhase.LANDING),  # roll-out
        (FIELD, v(10.0, 0.0), FlightPhase.TAXI),
    ]
    for alt, vel, expected in seq:
        assert pc.update(alt, vel) is expected, (alt, vel)


def test_landed_state_hints_and_learned_field_elevation() -> None:
    pc = PhaseClassifier()
    assert pc.update(250.0, v(0.0, 0.0), LandedState.ON_GROUND) is FlightPhase.TAXI
    assert pc.field_elevation_msl_m == 250.0
    assert pc.update(260.0, v(40.0, -3.0), LandedState.TAKEOFF) is FlightPhase.TAKEOFF
    assert pc.update(900.0, v(60.0, 0.0), LandedState.IN_AIR) is FlightPhase.ENROUTE
    assert pc.update(500.0, v(60.0, 3.0), LandedState.IN_AIR) is FlightPhase.APPROACH
    assert pc.update(400.0, v(60.0, 3.0), LandedState.LANDING) is FlightPhase.LANDING
    assert pc.update(250.0, v(50.0, 0.0), LandedState.ON_GROUND) is FlightPhase.LANDING


def test_no_field_elevation_in_the_air_is_en_route() -> None:
    pc = PhaseClassifier()
    assert pc.update(300.0, v(60.0, 3.0)) is FlightPhase.ENROUTE
    pc.reset()
    assert pc.phase is FlightPhase.TAXI


def test_non_finite_state_keeps_the_phase() -> None:
    pc = PhaseClassifier(PhaseConfig(field_elevation_msl_m=FIELD))
    pc.update(FIELD + 1000.0, v(60.0, 0.0))
    assert pc.update(float("nan"), v(60.0, 0.0)) is FlightPhase.ENROUTE


@pytest.mark.parametrize(
    "kwargs",
    [
        {"ground_height_m": 0.0},
        {"landing_height_m": 1000.0},
        {"vertical_speed_mps": float("nan")},
        {"field_elevation_msl_m": float("inf")},
    ],
)
def test_config_validation(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        PhaseConfig(**kwargs)


def test_a_parked_vehicle_with_a_vertical_speed_about_the_threshold_stays_taxiing() -> None:
    """Parked 2 m above the field, the published vertical speed wandering about -1 m/s (the
    threshold) as on the real ArduPlane log: without the dwell the phase flapped between taxi
    and take-off at every crossing. A real climb still becomes TAKEOFF after the dwell."""
    cfg = PhaseConfig(field_elevation_msl_m=FIELD)
    rng = np.random.default_rng(3)
    pc = PhaseClassifier(cfg)
    phases = set()
    t = 0.0
    for _ in range(6000):  # 10 min at 10 Hz
        vd = -1.0 + 0.1 * rng.standard_normal()
        phases.add(pc.update(FIELD + 2.0, v(0.1, vd), None, t))
        t += 0.1
    assert phases == {FlightPhase.TAXI}
    # the same without a time (no dwell): flaps, as before
    flapping = PhaseClassifier(cfg)
    seen = {
        flapping.update(FIELD + 2.0, v(0.1, -1.0 + 0.1 * rng.standard_normal())) for _ in range(100)
    }
    assert FlightPhase.TAKEOFF in seen
    # a real climb: take-off after the dwell, not before
    t_climb = t
    while pc.update(FIELD + 2.0 + 3.0 * (t - t_climb), v(2.0, -3.0), None, t) is FlightPhase.TAXI:
        t += 0.1
        assert t - t_climb < 10.0
    assert pc.phase is FlightPhase.TAKEOFF
    # (the candidate may have started with the last noisy samples, just before the climb)
    assert cfg.dwell_s - 0.5 <= t - t_climb <= cfg.dwell_s + 0.15


def test_the_autopilots_landed_state_is_taken_at_once() -> None:
    pc = PhaseClassifier(PhaseConfig(field_elevation_msl_m=FIELD))
    assert pc.update(FIELD, v(0.0, 0.0), LandedState.ON_GROUND, 0.0) is FlightPhase.TAXI
    assert pc.update(FIELD + 3.0, v(0.0, -2.0), LandedState.TAKEOFF, 0.1) is FlightPhase.TAKEOFF
