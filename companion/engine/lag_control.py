"""The lags the receivers' fixes are placed with, and every change of them told to the engine.

The decoder subtracts a lag per receiver from its fixes' stamps (``delay_s``, a list the
decoder owns and this class changes). It comes from the configuration
(``[decoder] gnss_delay_s``), else from the autopilot's parameter (``GPSn_DELAY_MS``),
else, for receiver 0, from the lag measured in flight (:mod:`.gnss_lag`), which also
replaces the parameter where they disagree. Receiver 0's lag is carried to a new value
by :class:`~companion.engine.lag_ramp.LagRamp` (never a step the navigator's tests can
see); receiver 1's, only ever the parameter's, changes at once. Each change is a change
of the service's own, told to the engine (:meth:`Engine.self_change`), as is the IMU
stamps' offset once the lag measurement takes it in.

Pure: samples and numbers in; no I/O, no clock.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import TYPE_CHECKING

from companion.engine.gnss_lag import LagTracker, MeasuredLag
from companion.engine.lag_ramp import LagRamp
from companion.nav.gnss import h_sigma_m
from companion.types import AttitudeSample, GnssFix, ImuSample

if TYPE_CHECKING:
    from companion.engine.core import Engine

log = logging.getLogger(__name__)


class LagControl:
    """Receiver lags in use (``delay_s``, the decoder's list), the measurement of receiver
    0's (``tracker``, None when ``measure`` is off) and the ramp that carries it in."""

    def __init__(
        self, engine: Engine, delay_s: list[float], configured_s: float, measure: bool
    ) -> None:
        self.engine = engine
        self.delay_s = delay_s
        self.configured_s = configured_s
        self.tracker = LagTracker() if measure else None
        self.ramp = LagRamp()
        self.ramp.start(delay_s[0], delay_s[0])
        self.measured_s: float | None = None
        """The measured lag receiver 0's fixes are (being) placed with (None: none taken)."""
        self.solution_h_acc_m = math.inf
        """The published solution's horizontal 1-sigma (inf: none yet), m."""
        self._last_fix: GnssFix | None = None
        """Receiver 0's latest fix (its speed and accuracy size the ramp's steps)."""

    # ------------------------------------------------------------------ samples

    def on_imu(self, sample: ImuSample) -> None:
        if self.tracker is not None:
            self.tracker.on_imu(sample)

    def on_attitude(self, sample: AttitudeSample) -> None:
        tracker = self.tracker
        if tracker is None:
            return
        tracker.on_attitude(sample)
        offset = tracker.take_offset()
        if offset is not None:
            self.engine.self_change(
                sample.t_s,
                "stamp",
                f"IMU stamps {offset.lag_s * 1000.0:.1f}+/-{offset.sigma_s * 1000.0:.1f} ms late "
                "(added to the lag measured)",
            )

    def on_fix(self, fix: GnssFix) -> MeasuredLag | None:
        """Take a fix (after the decoder placed it); returns receiver 0's lag when the
        measurement hands one out (:meth:`switch` carries it in), and steps the ramp."""
        tracker, ramp = self.tracker, self.ramp
        taken = None
        if tracker is not None:
            placed = fix
            if ramp.active and fix.receiver_id == 0:  # as the target will place it
                placed = dataclasses.replace(fix, t_s=ramp.placed_for(fix.t_s))
            tracker.on_fix(placed)
            taken = tracker.take()
        if fix.receiver_id == 0:
            self._last_fix = fix
            if ramp.active:
                self._step(fix.t_s)
        return taken

    # ------------------------------------------------------------------ changes

    def switch(self, target_s: float, t_s: float) -> None:
        """Place receiver 0's fixes with ``target_s`` (measured) from now on, carried in."""
        self.measured_s = target_s
        self._carry(target_s, t_s)

    def parameter(self, receiver: int, delay_s: float | None) -> None:
        """The autopilot's lag parameter for ``receiver`` (None: it gives none); the
        configuration, else a measurement, stand over it (:meth:`default_s`)."""
        if delay_s is None or (receiver == 0 and self.measured_s is not None):
            delay_s = self.default_s(receiver)
        now = self.engine.now_s
        if receiver == 0:
            if delay_s == self.ramp.target_s:
                return
            self._carry(delay_s, now)
        else:
            old = self.delay_s[receiver]
            if delay_s == old:
                return
            self.delay_s[receiver] = delay_s
            if now is not None:
                text = f"rx{receiver} placed with {delay_s * 1e3:.1f} ms (was {old * 1e3:.1f})"
                self.engine.self_change(now, "lag", text, receiver)
        log.info("GNSS receiver %d: fixes taken %.3f s before their arrival", receiver, delay_s)

    def default_s(self, receiver: int) -> float:
        """A receiver's lag where the autopilot's parameter gives none (or receiver 0's was
        measured): the configured one, else (receiver 0) the one measured, else 0."""
        if self.configured_s > 0.0 or receiver != 0 or self.measured_s is None:
            return self.configured_s
        return self.measured_s

    def restart(self) -> None:
        """The autopilot rebooted (the navigation restarts): receiver 0's target at once."""
        target = self.ramp.target_s
        self.ramp.start(target, target)
        self.delay_s[0] = target
        if self.tracker is not None:
            self.tracker.restart(target)

    def _carry(self, target_s: float, t_s: float | None) -> None:
        """Start carrying receiver 0's lag to ``target_s`` (the measurement compares with
        the target from now on); the first step at once, sized by the latest fix."""
        self.ramp.start(self.delay_s[0], target_s)
        if self.tracker is not None:
            self.tracker.restart(target_s)
        self._step(t_s)

    def _step(self, t_s: float | None) -> None:
        """One step of the ramp, sized by receiver 0's latest fix (none: at once)."""
        ramp, fix = self.ramp, self._last_fix
        old = ramp.in_use_s
        if fix is None:
            new = ramp.step(0.0, math.inf)
        else:
            sigma_m = math.hypot(h_sigma_m(fix), self.solution_h_acc_m)
            new = ramp.step(fix.ground_speed_mps, sigma_m)
        if new == old:
            return
        self.delay_s[0] = new
        if t_s is not None:
            text = (
                f"rx0 placed with {new * 1e3:.1f} ms "
                f"(was {old * 1e3:.1f}, to {ramp.target_s * 1e3:.1f})"
            )
            self.engine.self_change(t_s, "lag", text, 0)
        if not ramp.active:
            log.info("GNSS receiver 0: fixes placed with %.1f ms from now on", new * 1e3)
