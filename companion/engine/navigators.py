"""Which navigator carries the solution: the blend on a live IMU stream, else the fallback.

``EngineConfig.navigator`` chooses the set:

* ``blend``: the GNSS/INS blend (:mod:`companion.nav.blend`) is the primary; the GNSS
  pass-through (:mod:`companion.nav.passthrough`) is the fallback that takes over
  while no IMU sample is newer than ``imu_timeout_s``;
* ``singer``: the Singer manoeuvre model (:mod:`companion.nav.motion`) alone, no IMU;
* ``passthrough``: the pass-through alone.

While the blend carries the solution the fallback is fed lazily: its fixes wait in a
backlog and it takes them when it is next needed (it takes over, or the local frame
moves), not at every fix, where its result would be thrown away.
"""

from __future__ import annotations

import logging
import math
from collections import deque

from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.frames import LocalFrame
from companion.nav.motion import SingerConfig, SingerNavigator
from companion.nav.navigator import GnssMeasurement, GnssUpdate, Navigator
from companion.nav.passthrough import PassthroughConfig, PassthroughNavigator
from companion.types import AttitudeSample, ImuSample

log = logging.getLogger(__name__)

FALLBACK_BACKLOG_FIXES = 600
"""Fixes held for the fallback while the blend runs (a minute of a 10 Hz receiver)."""


class Navigators:
    """The primary navigator (the blend, if configured), the fallback, and the choice."""

    def __init__(self, kind: str, blend: BlendConfig, imu_timeout_s: float) -> None:
        """``kind`` is ``EngineConfig.navigator``; ``imu_timeout_s`` its IMU timeout."""
        self.fallback: Navigator = PassthroughNavigator(PassthroughConfig())
        self.primary: Navigator | None = None
        if kind == "blend":
            self.primary = BlendNavigator(blend)
        elif kind == "singer":
            self.fallback = SingerNavigator(SingerConfig())
        self.navigator: Navigator = self.fallback
        """The navigator carrying the solution now (the blend, or the fallback)."""
        self._imu_timeout_s = imu_timeout_s
        self.last_imu_t_s = -math.inf
        """Time of the newest IMU sample the primary took (s, autopilot clock)."""
        self.backlog: deque[tuple[GnssMeasurement, bool]] = deque(maxlen=FALLBACK_BACKLOG_FIXES)
        """Fixes (and their gate flags) the fallback has not taken yet."""
        self._backlog_overflowed = False
        """The backlog dropped fixes: the fallback restarts from the fixes it holds."""

    def all(self) -> list[Navigator]:
        """Every navigator kept up to date (the primary first)."""
        return [self.fallback] if self.primary is None else [self.primary, self.fallback]

    def on_imu(self, sample: ImuSample) -> bool:
        """An IMU sample for the primary; False when there is none (no IMU navigator)."""
        primary = self.primary
        if primary is None:
            return False
        primary.on_imu(sample)
        self.last_imu_t_s = sample.t_s
        return True

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> bool:
        """An attitude sample for the primary; False when there is none."""
        primary = self.primary
        if primary is None:
            return False
        primary.on_attitude(sample, yaw_correction_rad)
        return True

    def select(self, now_s: float | None) -> None:
        """The blend carries the solution while it runs on a live IMU stream."""
        primary = self.primary
        live = (
            primary is not None
            and primary.initialised
            and now_s is not None
            and now_s - self.last_imu_t_s <= self._imu_timeout_s
        )
        chosen = primary if live and primary is not None else self.fallback
        if chosen is not self.navigator:
            log.info("navigator: %s", type(chosen).__name__)
            if chosen is self.fallback:
                self.sync_fallback()
            self.navigator = chosen

    def on_gnss(self, meas: GnssMeasurement, gate: bool) -> GnssUpdate:
        """Offer a fix to the navigator carrying the solution (``gate``: test it against
        the prediction first); the other takes it too. Returns the carrying one's verdict."""
        primary = self.primary
        if primary is not None and self.navigator is primary:
            self.defer_to_fallback(meas, gate)
            return primary.on_gnss(meas, gate=gate)
        self.sync_fallback()
        update = self.fallback.on_gnss(meas, gate=gate)
        if primary is not None:
            primary.on_gnss(meas, gate=gate and primary.initialised)
        return update

    def reinitialise(self, meas: GnssMeasurement) -> None:
        """Restart every navigator from the fix ``meas`` (taken without a gate)."""
        self.backlog.clear()
        self._backlog_overflowed = False
        for nav in self.all():
            nav.reset()
            nav.on_gnss(meas, gate=False)

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        """Every navigator restarts its heading error at ``yaw_sigma_rad`` (1-sigma)."""
        for nav in self.all():
            nav.reset_heading(yaw_sigma_rad)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Carry every navigator's state from frame ``old`` to ``new`` (the same frame at
        anchoring, where the blend takes its gravity model from it)."""
        for nav in self.all():
            nav.shift_frame(old, new)

    def defer_to_fallback(self, meas: GnssMeasurement, gate: bool) -> None:
        """Keep a fix for the fallback, which takes it when it is next needed."""
        backlog = self.backlog
        if len(backlog) == backlog.maxlen:
            self._backlog_overflowed = True
        backlog.append((meas, gate))

    def sync_fallback(self) -> None:
        """Give the fallback the fixes it has not taken, in order, as it would have taken
        them one by one (restarted from the oldest held when some were dropped: the
        pass-through's state depends on the last fix and, through its vertical-velocity
        average, on earlier ones with weights (1 - k)^n: below 1e-90 after a full backlog
        with the default gain k = 0.3)."""
        backlog = self.backlog
        if not backlog:
            return
        fallback = self.fallback
        if self._backlog_overflowed:
            fallback.reset()
            self._backlog_overflowed = False
        for meas, gate in backlog:
            fallback.on_gnss(meas, gate=gate)
        backlog.clear()
