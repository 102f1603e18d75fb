"""When the potential filter refits α and G.

A refit runs every ``refit_interval_s`` of fix time, sooner when the
particle's speed has left a band around its speed at the last fit (a fit made
parked or taxiing is not carried into flight), and before the first
inconsistent fix of a run is rejected (at least ``refit_min_interval_s`` after
the last fit); the engine forces one at the start of a gap. The first fit, and
the first after a restart, waits until the window spans ``first_fit_span_s``.
"""

from __future__ import annotations

import math

from companion.nav.potential.anchor import Anchor
from companion.nav.potential.config import PotentialConfig


class RefitSchedule:
    """The fix time and particle speed of the last fit, and whether a fit is due."""

    __slots__ = ("config", "last_fit_speed", "last_fit_t")

    def __init__(self, config: PotentialConfig) -> None:
        self.config = config
        self.last_fit_t: float | None = None
        """Fix time of the last fit [s], None before the first."""
        self.last_fit_speed: float | None = None
        """The particle's speed at the last fit [m/s]."""

    def due(self, anc: Anchor, span_s: float) -> bool:
        """True when a fit is due at the anchor ``anc`` (the newest fix) with a window
        spanning ``span_s`` of fix time [s]."""
        c = self.config
        if self.last_fit_t is not None:
            since = anc.t_s - self.last_fit_t
            if since < c.refit_interval_s and not (
                since >= c.refit_min_interval_s and self.speed_changed(anc)
            ):
                return False
        return not span_s < min(c.refit_interval_s, c.first_fit_span_s)

    def allowed(self, anc: Anchor | None) -> bool:
        """True when ``refit_min_interval_s`` of fix time has passed since the last fit."""
        if anc is None or self.last_fit_t is None:
            return anc is not None
        return anc.t_s - self.last_fit_t >= self.config.refit_min_interval_s

    def speed_changed(self, anc: Anchor) -> bool:
        """True when the particle's speed left the band around its speed at the last fit."""
        v_fit = self.last_fit_speed
        if v_fit is None or not anc.vel_known:
            return False
        c = self.config
        v = math.sqrt(float(anc.vel_ned_mps @ anc.vel_ned_mps))
        return abs(v - v_fit) > c.refit_speed_change_mps + c.refit_speed_change_rel * v_fit
