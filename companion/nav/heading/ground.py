"""Is the vehicle on the ground? The autopilot's landed state, or a fallback inference.

The autopilot's EXTENDED_SYS_STATE is used whenever it is sent. Without it the
vehicle counts as on the ground while its ground speed is at most
``max_speed_mps`` (no take-off run), its height above the ground reference (the
mean altitude of the parked fixes, or the first fix) is at most
``ground_max_height_m`` and, when VFR_HUD is sent, its climb rate is at most
``ground_max_climb_mps`` in magnitude.

The inference is weak when the service starts in flight without
EXTENDED_SYS_STATE (the first fix then sets the ground reference): slow level
flight below ``max_speed_mps`` would be taken for taxiing. The engine should
pass the landed state whenever the autopilot sends it.
"""

from __future__ import annotations

import math

from companion.nav.heading.config import HeadingConfig
from companion.types import GnssFix


class GroundState:
    """Landed state, climb rate and ground reference altitude (m above MSL)."""

    def __init__(self, config: HeadingConfig) -> None:
        self.config = config
        self.explicit: bool | None = None
        """The autopilot's landed state; ``None`` when it does not send one."""
        self.climb_mps: float | None = None
        self.ref_alt_m: float | None = None
        self.ref_n = 0
        """Parked fixes averaged into ``ref_alt_m``."""

    def add_parked_altitude(self, alt_msl_m: float) -> None:
        """A parked fix: its altitude enters the mean ground reference (when finite)."""
        if math.isfinite(alt_msl_m):
            self.ref_n += 1
            ref = self.ref_alt_m if self.ref_alt_m is not None else alt_msl_m
            self.ref_alt_m = ref + (alt_msl_m - ref) / self.ref_n

    def on_ground(self, fix: GnssFix, speed_mps: float) -> bool:
        """On the ground at ``fix`` (ground speed ``speed_mps``)? See the module docstring."""
        if self.explicit is not None:
            return self.explicit
        alt = fix.alt_msl_m
        if not math.isfinite(alt):
            return False
        if self.ref_alt_m is None:
            self.ref_alt_m = alt
        if speed_mps > self.config.max_speed_mps:
            return False
        if abs(alt - self.ref_alt_m) > self.config.ground_max_height_m:
            return False
        return not (
            self.climb_mps is not None and abs(self.climb_mps) > self.config.ground_max_climb_mps
        )
