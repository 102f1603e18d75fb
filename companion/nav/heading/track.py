"""The GNSS track angle of a cycle from positions (``track_source = "position"``).

The direction of the displacement between two fixes ``pos_baseline_s`` apart on
the same straight leg, one cycle per baseline (non-overlapping, so that cycles
stay independent). With RTK positions it is far less noisy than the Doppler
velocity track ``atan2(V_E, V_N)`` of Markelov et al. at taxi speeds; the
recursions and criteria are the same (an extension of the method).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from companion.nav.earth import radii_of_curvature_m
from companion.nav.heading.config import HeadingConfig
from companion.nav.rotations import wrap_pi
from companion.types import GnssFix


class PositionTrack:
    """The start fix of the current baseline; ``reject`` is called with the reason of
    every fix not used."""

    def __init__(self, config: HeadingConfig, reject: Callable[[str], None]) -> None:
        self.config = config
        self._reject = reject
        self._prev: tuple[float, float, float, int] | None = None  # (t, lat, lon, fix type)

    def reset(self) -> None:
        """The leg ended: the next fix starts a new baseline."""
        self._prev = None

    def track(self, fix: GnssFix) -> tuple[float, float, float] | None:
        """Track angle (rad), its variance (rad^2) and mid time (s) from the displacement.

        The displacement since the fix ``pos_baseline_s`` earlier on the same straight
        leg, north and east on the ellipsoid (meridian and prime-vertical radii);
        ``None`` until a baseline is complete.
        """
        cfg = self.config
        here = (fix.t_s, fix.lat_rad, fix.lon_rad, int(fix.fix_type))
        prev = self._prev
        if fix.fix_type < cfg.pos_min_fix_type or not (
            math.isfinite(fix.lat_rad) and math.isfinite(fix.lon_rad)
        ):
            self._prev = None
            self._reject("position_fix_type")
            return None
        if prev is None or prev[3] != here[3] or fix.t_s - prev[0] > 2.0 * cfg.pos_baseline_s:
            self._prev = here
            return None
        dt = fix.t_s - prev[0]
        if dt < cfg.pos_baseline_s - 1e-6:
            return None
        self._prev = here
        m_m, n_m = radii_of_curvature_m(0.5 * (fix.lat_rad + prev[1]))
        d_n = (fix.lat_rad - prev[1]) * m_m
        d_e = wrap_pi(fix.lon_rad - prev[2]) * n_m * math.cos(fix.lat_rad)
        dist = math.hypot(d_n, d_e)
        if dist < cfg.min_speed_mps * dt:
            self._reject("slow")
            return None
        var = 2.0 * cfg.pos_diff_sigma_m**2 / dist**2
        return math.atan2(d_e, d_n), var, 0.5 * (fix.t_s + prev[0])
