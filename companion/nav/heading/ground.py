"""Is the vehicle on the ground? Decided from the motion, the autopilot's landed state
one input.

Motion evidence of flight, at a fix: a ground speed above ``max_speed_mps`` (beyond
a taxi), a height above the ground reference beyond ``ground_max_height_m``, a
climb rate (VFR_HUD) beyond ``ground_max_climb_mps`` or a pitch (ATTITUDE) beyond
``ground_max_pitch_deg`` in magnitude. The ground reference is the mean altitude
of the parked fixes, else the first fix taken as on the ground.

With the autopilot's landed state (EXTENDED_SYS_STATE):

* "on ground" is trusted: on the ground, and a flight (:attr:`GroundState.airborne`)
  is over; the ground reference restarts at the next fix after a flight.
* "in air" (or taking off, landing) needs corroboration: ArduPlane reports "in air"
  as soon as it rolls at a few m/s. It makes a flight only with motion evidence of
  flight, or when no ground reference is known yet (the service started in the air).
  Without either the vehicle is taken as taxiing.
* After a flight, while the autopilot still says "in air", the taxi resumes when the
  motion has shown the ground (no evidence of flight, within
  ``ground_release_height_m`` of the reference) for ``ground_release_s``.

Without a landed state each fix is decided by the motion alone and there is no
flight to latch (:attr:`GroundState.airborne` stays False). That inference is weak
when the service starts in flight (the first fix then sets the ground reference):
slow level flight would be taken for taxiing.
"""

from __future__ import annotations

import math

from companion.nav.heading.config import HeadingConfig
from companion.types import GnssFix


class GroundState:
    """Landed state, climb rate, pitch, ground reference altitude (m above MSL) and the
    current flight."""

    def __init__(self, config: HeadingConfig) -> None:
        self.config = config
        self.explicit: bool | None = None
        """The autopilot's landed state: on ground, not on ground, ``None`` when not sent."""
        self.climb_mps: float | None = None
        self.pitch_rad: float | None = None
        self.ref_alt_m: float | None = None
        self.ref_n = 0
        """Parked fixes averaged into ``ref_alt_m``."""
        self.airborne = False
        """In a flight corroborated by the motion (only with a landed state)."""
        self._rebase = False
        """A flight ended on the autopilot's word: the next fix restarts the reference."""
        self._ground_since_s: float | None = None
        """After a flight: since when the motion shows the ground."""
        self._last: tuple[float, bool] | None = None
        """The decision at the last fix's time (asked once per fix, answered alike)."""

    def set_landed(self, on_ground: bool | None) -> None:
        """The autopilot's landed state (``None``: not sent or undefined)."""
        self.explicit = on_ground
        if on_ground is None:
            self.airborne = False
        elif on_ground and self.airborne:
            self.airborne = False
            self._rebase = True
        self._last = None

    def add_parked_altitude(self, alt_msl_m: float) -> None:
        """A parked fix: its altitude enters the mean ground reference (when finite)."""
        if math.isfinite(alt_msl_m):
            self.ref_n += 1
            ref = self.ref_alt_m if self.ref_alt_m is not None else alt_msl_m
            self.ref_alt_m = ref + (alt_msl_m - ref) / self.ref_n

    def on_ground(self, fix: GnssFix, speed_mps: float) -> bool:
        """On the ground at ``fix`` (ground speed ``speed_mps``)? See the module docstring."""
        if self._last is not None and self._last[0] == fix.t_s:
            return self._last[1]
        verdict = self._decide(fix, speed_mps)
        self._last = (fix.t_s, verdict)
        return verdict

    def _decide(self, fix: GnssFix, speed_mps: float) -> bool:
        alt = fix.alt_msl_m
        finite = math.isfinite(alt)
        if self.explicit is True:
            if finite and (self._rebase or self.ref_alt_m is None):
                self.ref_alt_m, self.ref_n, self._rebase = alt, 0, False
            return True
        if not finite:
            return False
        if self.explicit is None:
            if self.ref_alt_m is None:
                self.ref_alt_m = alt
            return not self._flight_evidence(speed_mps, alt)
        # the autopilot says "in air": corroborated by the motion, or not
        if self.ref_alt_m is None or self._flight_evidence(speed_mps, alt):
            self.airborne = True
            self._ground_since_s = None
            return False
        if not self.airborne:
            return True
        if abs(alt - self.ref_alt_m) > self.config.ground_release_height_m:
            self._ground_since_s = None
            return False
        if self._ground_since_s is None or fix.t_s < self._ground_since_s:
            self._ground_since_s = fix.t_s
        if fix.t_s - self._ground_since_s < self.config.ground_release_s:
            return False
        self.airborne = False
        self._ground_since_s = None
        return True

    def _flight_evidence(self, speed_mps: float, alt_msl_m: float) -> bool:
        """Any motion that a taxi does not have (the reference is set)."""
        cfg = self.config
        ref = self.ref_alt_m if self.ref_alt_m is not None else alt_msl_m
        climb, pitch = self.climb_mps, self.pitch_rad
        return (
            speed_mps > cfg.max_speed_mps
            or abs(alt_msl_m - ref) > cfg.ground_max_height_m
            or (climb is not None and abs(climb) > cfg.ground_max_climb_mps)
            or (pitch is not None and abs(math.degrees(pitch)) > cfg.ground_max_pitch_deg)
        )
