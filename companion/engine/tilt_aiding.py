"""Whether the autopilot's filter still levels its attitude once it has lost GNSS.

A navigation filter tells its tilt from the vehicle's accelerations by a velocity it
fuses: GNSS, or an airspeed (with a wind estimate) on a fixed wing. Without GNSS a
multirotor's has nothing of the kind (ArduPilot EKF3 and PX4 EKF2 without optical flow,
external vision or drag fusion set up): its tilt error then grows as a strapdown's. Two
pieces of the autopilot's own evidence are taken:

* its airframe (HEARTBEAT ``type``): a multirotor or a helicopter has no airspeed;
* its own position held still: a filter that loses its last position source fuses a
  constant position (ArduPilot EKF3's constant-position mode, "stopped aiding"), so the
  position it reports (GLOBAL_POSITION_INT) stops moving to the last bit while the
  vehicle flies on; a real solution moves by its noise at that 1e-7 deg (1 cm)
  resolution within a second, even parked.
"""

from __future__ import annotations

import math

HOLD_S = 1.0
"""The same position for this long (autopilot time, s) is a held one."""
NO_AIRSPEED_TYPES = frozenset({2, 3, 4, 13, 14, 15, 29, 35, 43})
"""MAV_TYPE of airframes without an airspeed: QUADROTOR, COAXIAL, HELICOPTER, HEXAROTOR,
OCTOROTOR, TRICOPTER, DODECAROTOR, DECAROTOR, GENERIC_MULTIROTOR."""


class TiltAiding:
    """Follows the autopilot's HEARTBEAT and GLOBAL_POSITION_INT: :attr:`lost` when,
    without GNSS, nothing would level its tilt."""

    def __init__(self) -> None:
        self.no_airspeed = False
        """The autopilot's airframe has no airspeed (:data:`NO_AIRSPEED_TYPES`)."""
        self._since: tuple[float, float, float] | None = None
        """``(t_s, lat_rad, lon_rad)`` of the first solution at the current position."""
        self.held = False
        """The autopilot holds its own position still (for :data:`HOLD_S`)."""
        self.held_episodes = 0
        """Times its position was found held."""

    @property
    def lost(self) -> bool:
        """Without GNSS, the autopilot's tilt is not aided."""
        return self.no_airspeed or self.held

    def on_heartbeat(self, vehicle_type: int) -> None:
        """The autopilot's HEARTBEAT ``type`` (MAV_TYPE)."""
        self.no_airspeed = vehicle_type in NO_AIRSPEED_TYPES

    def on_solution(self, t_s: float, lat_rad: float, lon_rad: float) -> bool:
        """One solution of the autopilot's; returns :attr:`held` after it."""
        if not (math.isfinite(t_s) and math.isfinite(lat_rad) and math.isfinite(lon_rad)):
            return self.held
        since = self._since
        if since is None or t_s < since[0] or (lat_rad, lon_rad) != since[1:]:
            self._since = (t_s, lat_rad, lon_rad)
            self.held = False
        elif not self.held and t_s - since[0] >= HOLD_S:
            self.held = True
            self.held_episodes += 1
        return self.held
