"""The position-potential filter's uses in the engine, and its life cycle.

Grzegorzewski (2005), "Navigating by a position potential in 3-D", predicts the
position through a GNSS gap from the last fused fixes alone (:mod:`companion.nav.potential`).
The engine uses it, as ``EngineConfig`` says, in up to three ways:

* ``potential_bridge``: without an IMU stream, the published state through a gap
  (BRIDGING, LOST) is the filter's prediction instead of the pass-through's constant
  velocity;
* ``potential_combine``: with an IMU stream, the published state through a gap is the
  INS and potential predictions combined by their covariances
  (:func:`~companion.nav.potential.combine_with_ins`) while the two agree (chi-square
  test at ``PotentialConfig.false_alarm_prob``, 3 degrees of freedom); after the first
  disagreement the INS alone to the gap's end;
* ``potential_fix_test``: the prediction at each new fix of the fused receiver is the
  integrity monitor's reference for the ellipsoid test of that fix.

Only the fix test needs the filter fed at every fused fix. For the bridges alone the
last ``PotentialConfig.window_s`` of fused fixes are kept and the filter is built from
them when a gap starts: the same state, without fitting alpha and G every few seconds
of flight for nothing.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import replace

import numpy as np
from scipy.stats import chi2

from companion.engine.config import EngineConfig
from companion.nav.navigator import GnssMeasurement, NavState
from companion.nav.potential import (
    PotentialConfig,
    PotentialFilter,
    PotentialPrediction,
    combine_with_ins,
)
from companion.types import NamedValue, NavMode

log = logging.getLogger(__name__)

GAP_MODES = (NavMode.BRIDGING, NavMode.LOST)
"""Outage modes in which the published state is bridged."""


class PotentialBridge:
    """The potential filter on the fused fixes, when one of its uses is configured."""

    def __init__(self, config: EngineConfig, potential: PotentialConfig) -> None:
        self._config = potential
        self._bridge_without_imu = config.potential_bridge
        self._combine_with_ins = config.potential_combine
        self._fix_test = config.potential_fix_test
        self._used = (
            config.potential_bridge or config.potential_combine or config.potential_fix_test
        )
        self._combine_threshold = float(chi2.isf(potential.false_alarm_prob, 3))
        """Chi-square bound (3 dof) of the INS/potential consistency test."""
        self.potential: PotentialFilter | None = None
        """The filter: fed at every fused fix for the fix test, else built when a gap starts."""
        self._recent_fixes: deque[GnssMeasurement] = deque()
        self._gap_ready = False
        """The filter is ready for this gap (cleared by the next fused fix)."""
        self._disagrees = False
        """The potential and INS predictions failed their consistency test in this gap."""

    def add_fix(self, meas: GnssMeasurement) -> None:
        """A fused fix becomes a source of the potential field (refitted when due)."""
        self._gap_ready = False
        if not self._used:
            return
        if self._fix_test:
            if self.potential is None:
                self.potential = PotentialFilter(self._config)
            self.potential.add_fix(meas.t_s, meas.pos_ned_m, meas.pos_var_ned_m2, meas.vel_ned_mps)
            return
        recent = self._recent_fixes
        recent.append(meas)
        horizon_s = self._config.window_s
        while recent and meas.t_s - recent[0].t_s > horizon_s:
            recent.popleft()

    def restart(self) -> None:
        """Forget the fixes (the navigation restarted, or they are in a frame left behind:
        the window refills in seconds)."""
        self._recent_fixes.clear()
        if self.potential is not None:
            self.potential.reset()

    def reference(self, t_s: float) -> NavState | None:
        """The potential prediction at a new fix's time, for the integrity monitor's
        ellipsoid test (None unless configured, and until its covariance is calibrated by
        a first fit)."""
        pot = self.potential
        if pot is None or not self._fix_test:
            return None
        if not pot.calibrated or pot.t_last_s is None:
            return None
        if t_s <= pot.t_last_s:
            return None
        return potential_state(pot.predict(t_s))

    def carry(self, state: NavState, t_s: float, mode: NavMode, no_imu: bool) -> NavState:
        """The state to publish at ``t_s`` for the navigator's ``state``: through a gap
        (``mode`` BRIDGING or LOST) the potential filter's without an IMU (``no_imu``: the
        fallback carries the solution), optionally combined with the INS's with one."""
        if mode not in GAP_MODES:
            return state
        if not (self._bridge_without_imu if no_imu else self._combine_with_ins):
            return state
        if not self._gap_ready:
            self._gap_ready = True
            self._disagrees = False
            self._filter_for_gap()
        pot = self.potential
        if pot is None or pot.t_last_s is None or t_s < pot.t_last_s:
            return state
        pred = pot.predict(t_s)
        if no_imu:
            # the filter's covariance knows nothing of a manoeuvre begun in the gap; the
            # pass-through's grows with the manoeuvres of the flight so far: the larger
            bridged = potential_state(pred, state.yaw_rad)
            if np.trace(state.pos_cov_ned_m2[:2, :2]) > np.trace(bridged.pos_cov_ned_m2[:2, :2]):
                bridged = replace(
                    bridged,
                    pos_cov_ned_m2=state.pos_cov_ned_m2,
                    vel_cov_ned_m2ps2=state.vel_cov_ned_m2ps2,
                )
            return bridged
        if self._disagrees:
            return state  # once they disagreed in this gap, the INS alone to its end
        pos, cov, chi2_ = combine_with_ins(
            state.pos_ned_m, state.pos_cov_ned_m2, pred, self._combine_threshold
        )
        if chi2_ > self._combine_threshold:
            self._disagrees = True
            log.info(
                "t=%.2f s: potential prediction disagrees with the INS (chi2 %.1f)", t_s, chi2_
            )
            return state
        return replace(state, pos_ned_m=pos, pos_cov_ned_m2=cov)

    def status_values(self, t_s: float) -> list[NamedValue]:
        """The filter's status values (``CMP_PALPHA``, ``CMP_PG`` ...), once it exists."""
        return self.potential.outputs(t_s) if self.potential is not None else []

    def _filter_for_gap(self) -> None:
        """The filter at the start of a gap, alpha and G refitted on the fixes just before
        it (built from the recent fixes unless it is fed at every fix)."""
        if not self._fix_test and self._recent_fixes:
            pot = PotentialFilter(self._config)
            for m in self._recent_fixes:
                pot.add_fix(m.t_s, m.pos_ned_m, m.pos_var_ned_m2, m.vel_ned_mps)
            self.potential = pot
        if self.potential is not None:
            self.potential.refit(force=True)


def potential_state(pred: PotentialPrediction, yaw_rad: float | None = None) -> NavState:
    """A potential prediction as a navigator state (with the heading ``yaw_rad``, if known)."""
    return NavState(
        pred.t_s, pred.pos_ned_m, pred.vel_ned_mps, pred.cov_ned_m2, pred.vel_cov_ned_m2ps2, yaw_rad
    )
