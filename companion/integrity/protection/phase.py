"""Flight phase from the navigation state: taxi, take-off, en-route, approach, landing.

The phase decides which alert limit applies (:mod:`companion.integrity.protection.limits`).
Inputs are the published solution (height, ground speed, vertical speed) and,
when the autopilot sends EXTENDED_SYS_STATE, its landed state. Height above the
field is the altitude less the field elevation, which is configured or learned
while the aircraft is on the ground.

Rules (first match wins):

* on the ground (landed state ON_GROUND, or below ``ground_height_m`` with a
  small vertical speed): LANDING while rolling out after a flight (ground speed
  above ``taxi_max_speed_mps``), TAKEOFF on a take-off roll, TAXI otherwise;
* landed state TAKEOFF / LANDING is taken as given;
* descending below ``landing_height_m``: LANDING (the CAT II decision height
  region and the flare);
* descending below ``terminal_height_m``, or level there after an approach:
  APPROACH;
* climbing below ``terminal_height_m``: TAKEOFF (departure);
* otherwise EN-ROUTE. With no field elevation known the phase is EN-ROUTE
  in the air (the loosest airborne limit is not claimed tighter than known).

A phase the rules give from the navigation state alone is taken only once they have
given it for ``dwell_s`` without a break (sustained evidence: a vertical speed
hovering about ``vertical_speed_mps`` on a parked vehicle must not make it flap between
taxi, take-off and landing, each with its own alert limit); one the autopilot's landed
state decides is taken at once, and so is the first.

References
----------
ICAO Doc 8168 (PANS-OPS): decision heights 200 ft CAT I, 100 ft CAT II;
the terminal area below 1500 ft above the aerodrome for approach/departure.
Grzegorzewski (2005), "Navigating by a position potential in 3-D" (requirements
per flight phase); El-Mowafy (2005), RTK networks for precision approach with an
adaptive GPS/INS blend (take-off and landing as the hardest phases).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.integrity.protection.limits import FlightPhase
from companion.ranges import check_ranges, ranged
from companion.types import FloatArray, LandedState

FT_M = 0.3048
"""One foot, m."""


@dataclass(frozen=True, slots=True)
class PhaseConfig:
    """Thresholds of the phase rules (see the module docstring)."""

    field_elevation_msl_m: float | None = ranged(None, optional=True)
    """Aerodrome elevation; None: learned on the ground."""
    ground_height_m: float = ranged(5.0, gt=0.0)
    """Below this height above the field with a small vertical speed: on the ground."""
    landing_height_m: float = ranged(100.0 * FT_M, gt=0.0)
    """CAT II decision height (100 ft): below it, descending, the phase is LANDING."""
    terminal_height_m: float = ranged(1500.0 * FT_M, gt=0.0)
    """Below 1500 ft above the field a descent is an APPROACH, a climb a departure."""
    vertical_speed_mps: float = ranged(1.0, gt=0.0)
    """Vertical speed that counts as climbing / descending (a 3 deg glide at 20 m/s is 1 m/s)."""
    taxi_max_speed_mps: float = ranged(15.0, gt=0.0)
    """Ground speed above which a ground run is a take-off roll or landing roll-out."""
    stationary_speed_mps: float = ranged(0.5, gt=0.0)
    """Below this ground speed a first solution with no landed state is taken as on ground."""
    dwell_s: float = ranged(3.0, ge=0.0)
    """A phase inferred from the navigation state (no landed state) is taken once the rules
    have given it this long without a break, s."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if not self.ground_height_m < self.landing_height_m < self.terminal_height_m:
            raise ValueError("need ground_height_m < landing_height_m < terminal_height_m")


class PhaseClassifier:
    """Keeps the phase and the field elevation (see the module docstring)."""

    def __init__(self, config: PhaseConfig | None = None) -> None:
        self.config = config or PhaseConfig()
        self.field_elevation_msl_m: float | None = self.config.field_elevation_msl_m
        self.reset()

    def reset(self) -> None:
        """Forget the phase and any learned field elevation."""
        self.field_elevation_msl_m = self.config.field_elevation_msl_m
        self.phase = FlightPhase.TAXI
        self._been_airborne = False
        self._started = False
        self._candidate = FlightPhase.TAXI
        self._candidate_since_s = -math.inf

    def update(
        self,
        alt_msl_m: float,
        vel_ned_mps: FloatArray,
        landed: LandedState | None = None,
        t_s: float | None = None,
    ) -> FlightPhase:
        """Classify one state; returns (and keeps) the phase.

        Parameters
        ----------
        alt_msl_m : altitude, m MSL.
        vel_ned_mps : (3,) velocity, NED, m/s (down positive).
        landed : the autopilot's landed state, None when not reported.
        t_s : the state's time, s (None: every phase is taken at once, no dwell).
        """
        cfg = self.config
        vn, ve, vd = (
            vel_ned_mps.tolist() if isinstance(vel_ned_mps, np.ndarray) else map(float, vel_ned_mps)
        )
        speed = math.hypot(vn, ve)
        if not (math.isfinite(speed) and math.isfinite(vd) and math.isfinite(alt_msl_m)):
            return self.phase
        if landed is LandedState.ON_GROUND and self.config.field_elevation_msl_m is None:
            self.field_elevation_msl_m = alt_msl_m
        if (
            self.field_elevation_msl_m is None
            and landed is None
            and speed < cfg.stationary_speed_mps
            and abs(vd) < cfg.vertical_speed_mps
        ):
            self.field_elevation_msl_m = alt_msl_m
        height = (
            alt_msl_m - self.field_elevation_msl_m
            if self.field_elevation_msl_m is not None
            else None
        )
        been_airborne = self._been_airborne
        phase = self._classify(height, speed, vd, landed)
        if phase is not self._candidate:
            self._candidate = phase
            self._candidate_since_s = -math.inf if t_s is None else t_s
        sure = (
            not self._started
            or t_s is None
            or landed not in (None, LandedState.UNDEFINED)
            or t_s - self._candidate_since_s >= self.config.dwell_s
        )
        self._started = True
        if sure:
            self.phase = phase
        elif phase is not self.phase:
            self._been_airborne = been_airborne  # not taken: nor what it implies
        return self.phase

    def _classify(
        self, height: float | None, speed: float, vd: float, landed: LandedState | None
    ) -> FlightPhase:
        cfg = self.config
        on_ground = landed is LandedState.ON_GROUND or (
            landed is None
            and height is not None
            and height < cfg.ground_height_m
            and abs(vd) < cfg.vertical_speed_mps
        )
        if on_ground:
            if speed <= cfg.taxi_max_speed_mps:
                self._been_airborne = False
                return FlightPhase.TAXI
            if self._been_airborne or self.phase is FlightPhase.LANDING:
                return FlightPhase.LANDING
            return FlightPhase.TAKEOFF
        if landed is LandedState.TAKEOFF:
            return FlightPhase.TAKEOFF
        self._been_airborne = True
        if landed is LandedState.LANDING:
            return FlightPhase.LANDING
        if height is None:
            return FlightPhase.ENROUTE
        descending = vd > cfg.vertical_speed_mps
        climbing = vd < -cfg.vertical_speed_mps
        if height < cfg.landing_height_m and (descending or self.phase is FlightPhase.LANDING):
            return FlightPhase.LANDING
        if height < cfg.terminal_height_m:
            if descending:
                return FlightPhase.APPROACH
            if climbing:
                return FlightPhase.TAKEOFF
            if self.phase in (FlightPhase.APPROACH, FlightPhase.LANDING, FlightPhase.TAKEOFF):
                return self.phase
        return FlightPhase.ENROUTE
