"""What the engine publishes at a publication tick.

* the :class:`~companion.types.NavSolution`: the carried state converted to latitude,
  longitude and altitude, with the outage mode, an honest fix type (never RTK while
  bridging, no fix when lost) and, while the integrity monitor says integrity is lost,
  no fix and accuracies at least its floor;
* the integrity monitor's outputs for that solution (alerts, protection levels);
* at each status tick (``EngineConfig.status_rate_hz``) the status values
  ``CMP_HACC``, ``CMP_VACC`` (1-sigma accuracies, m), ``CMP_OUTG`` (time since the last
  fused fix, s), the potential filter's and ``CMP_HDGS`` (the taxi heading correction's
  :class:`~companion.nav.heading.HeadingStatus`).

The names are those of docs/mavlink.md; the publication clock itself is the engine's
(:mod:`companion.engine.core`).
"""

from __future__ import annotations

import math
from dataclasses import replace

from companion.engine.bridge import PotentialBridge
from companion.integrity.monitor import IntegrityMonitor
from companion.nav.frames import LocalFrame
from companion.nav.heading import HeadingCorrector
from companion.nav.navigator import NavState
from companion.nav.outage import OUTAGE_MODES, OutageMonitor
from companion.nav.rotations import wrap_2pi
from companion.types import (
    FixType,
    GnssFix,
    LandedState,
    NamedValue,
    NavMode,
    NavSolution,
    Output,
)


def publication_time_s(now_s: float) -> float:
    """The time a solution published at ``now_s`` is carried to: the next whole
    millisecond (GLOBAL_POSITION_INT's ``time_boot_ms`` is what a receiver aligns it by)."""
    return math.ceil(now_s * 1000.0 - 1e-6) / 1000.0


def tick(t_s: float, rate_hz: float) -> int:
    """Index of the publication period containing ``t_s`` (robust to 0.1 not being binary)."""
    return math.floor(t_s * rate_hz + 1e-6)


class Publisher:
    """Builds the outputs of each publication tick (see the module docstring)."""

    def __init__(
        self,
        status_rate_hz: float,
        outage: OutageMonitor,
        integrity: IntegrityMonitor,
        bridge: PotentialBridge,
    ) -> None:
        self._status_rate_hz = status_rate_hz
        self._outage = outage
        self._integrity = integrity
        self._bridge = bridge
        self._status_tick = -1
        self._status_outage: bool | None = None
        """Whether the last status values were published in an outage (None: none yet)."""
        self.last_fused_fix: GnssFix | None = None
        """The newest fix fused (or re-initialised from): its type bounds the published one."""
        self.satellites = 0
        """Satellites of the newest fused fix."""

    def set_status_rate(self, status_rate_hz: float, now_s: float | None) -> None:
        """Publish the status values at ``status_rate_hz`` from now on; the next status
        tick is the first of the new rate after ``now_s`` (a lower rate does not wait for
        its period index to catch up with the old one)."""
        self._status_rate_hz = status_rate_hz
        self._status_tick = -1 if now_s is None else tick(now_s, status_rate_hz)

    def publish(
        self,
        t_s: float,
        state: NavState,
        frame: LocalFrame,
        heading: HeadingCorrector,
        attitude_yaw_rad: float | None,
        landed: LandedState | None,
    ) -> list[Output]:
        """The solution for ``state`` (valid at ``t_s``, in ``frame``) first, then the
        integrity monitor's outputs and, when a status tick is due, the status values.
        The heading is the state's, else the autopilot's ``attitude_yaw_rad`` corrected by
        ``heading``; ``landed`` is the autopilot's landed state."""
        lat, lon, alt = frame.ned_to_lla(state.pos_ned_m)
        mode = self._outage.mode
        solution = NavSolution(
            t_s=t_s,
            lat_rad=lat,
            lon_rad=lon,
            alt_msl_m=alt,
            vel_ned_mps=state.vel_ned_mps,
            pos_cov_ned_m2=state.pos_cov_ned_m2,
            vel_cov_ned_m2ps2=state.vel_cov_ned_m2ps2,
            yaw_rad=published_yaw(state, heading, attitude_yaw_rad),
            mode=mode,
            fix_type=honest_fix_type(mode, self.last_fused_fix),
            satellites=self.satellites,
        )
        integrity = self._integrity
        outputs: list[Output] = list(integrity.on_solution(solution, landed))
        if not integrity.integrity_ok:
            solution = integrity_lost(solution, integrity.accuracy_floor_m())
        elif integrity.spoof.episodes:
            solution = widened(solution, integrity.accuracy_floor_m())
        outputs.insert(0, solution)
        status_tick = tick(t_s, self._status_rate_hz)
        in_outage = mode in OUTAGE_MODES
        # at the status rate, and at once when an outage begins or ends (CMP_OUTG must not
        # say "outage" for a second after the fix that ended it)
        if status_tick > self._status_tick or in_outage is not self._status_outage:
            self._status_tick = status_tick
            self._status_outage = in_outage
            outputs += [
                NamedValue(t_s, "CMP_HACC", solution.h_acc_m),
                NamedValue(t_s, "CMP_VACC", solution.v_acc_m),
                NamedValue(t_s, "CMP_OUTG", self._outage.outage_s(t_s)),
                *self._bridge.status_values(t_s),
                NamedValue(t_s, "CMP_HDGS", float(heading.status)),
            ]
        return outputs


def published_yaw(
    state: NavState, heading: HeadingCorrector, attitude_yaw_rad: float | None
) -> float | None:
    """The published heading in [0, 2 pi): the navigator's, else the autopilot's corrected
    by the taxi heading correction, else unknown."""
    if state.yaw_rad is not None:
        return wrap_2pi(state.yaw_rad)
    if attitude_yaw_rad is not None:
        return wrap_2pi(heading.corrected_yaw_rad(attitude_yaw_rad))
    return None


def honest_fix_type(mode: NavMode, last_fused_fix: GnssFix | None) -> FixType:
    """What the solution is in ``mode``: no fix when lost or not started, a 3-D fix
    while bridging or reacquiring, else the last fused fix's type (at most RTK fixed)."""
    if mode in (NavMode.LOST, NavMode.INIT) or last_fused_fix is None:
        return FixType.NO_FIX
    if mode in (NavMode.BRIDGING, NavMode.REACQUIRING):
        return FixType.FIX_3D
    return FixType(min(int(last_fused_fix.fix_type), int(FixType.RTK_FIXED)))


def integrity_lost(solution: NavSolution, floor_m: tuple[float, float]) -> NavSolution:
    """The solution as published while integrity is lost: no fix, accuracies at least
    the monitor's floor (the size of the unexplained disagreement; horizontal and
    vertical, m)."""
    return replace(widened(solution, floor_m), fix_type=FixType.NO_FIX)


def widened(solution: NavSolution, floor_m: tuple[float, float]) -> NavSolution:
    """The solution with its position variances at least the floors' squares (horizontal
    and vertical 1-sigma, m)."""
    h_floor, v_floor = floor_m
    cov = solution.pos_cov_ned_m2
    if cov[0, 0] >= h_floor**2 and cov[1, 1] >= h_floor**2 and cov[2, 2] >= v_floor**2:
        return solution
    cov = cov.copy()
    for axis, floor in ((0, h_floor), (1, h_floor), (2, v_floor)):
        cov[axis, axis] = max(cov[axis, axis], floor**2)
    return replace(solution, pos_cov_ned_m2=cov)
