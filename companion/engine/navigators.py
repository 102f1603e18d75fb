"""Which navigator carries the solution: the blend on a usable IMU stream, else the fallback.

``EngineConfig.navigator`` chooses the set:

* ``blend``: the GNSS/INS blend (:mod:`companion.nav.blend`) is the primary; the GNSS
  pass-through (:mod:`companion.nav.passthrough`) is the fallback that takes over
  while no IMU sample is newer than ``imu_timeout_s``, or while the IMU's measured
  rate is below ``min_imu_rate_hz`` (:class:`ImuRate`: an IMU delivered at 10 Hz, or
  at 1 Hz through a telemetry radio, cannot dead-reckon; constant velocity, whose
  covariance grows honestly, carries instead). The blend takes over again only after
  the rate has held for ``imu_rate_hold_s`` (no flapping between navigators), and
  restarts from the next fix (what it integrated meanwhile is not trusted);
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

from scipy.stats import chi2

from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.frames import LocalFrame
from companion.nav.motion import SingerConfig, SingerNavigator
from companion.nav.navigator import GnssMeasurement, GnssUpdate, Navigator, NavState
from companion.nav.passthrough import PassthroughConfig, PassthroughNavigator
from companion.types import AttitudeSample, ImuSample

log = logging.getLogger(__name__)

FALLBACK_BACKLOG_FIXES = 600
"""Fixes held for the fallback while the blend runs (a minute of a 10 Hz receiver)."""


VERTICAL_GATE_CHI2 = float(chi2.isf(1e-4, 1))
"""The height innovation's own gate (1 dof, false-alarm probability 1e-4: 15.1)."""


def vertical_within_gate(update: GnssUpdate) -> bool:
    """Is the height part of a position innovation within :data:`VERTICAL_GATE_CHI2`?"""
    s_dd = float(update.innovation_cov[2, 2])
    if not s_dd > 0.0 or not math.isfinite(s_dd):
        return False
    d = float(update.innovation[2])
    return d * d / s_dd <= VERTICAL_GATE_CHI2


IMU_RATE_WINDOW_S = 2.0
"""The IMU's rate is measured over windows of this length (autopilot clock)."""


class ImuRate:
    """The IMU's measured sample rate and whether it can support dead reckoning.

    Samples with a time not after the previous one (the same sample from a second
    MAVLink stream) are not counted. Unknown before the first window closes (then the
    IMU counts as usable: a healthy stream is not held back at start-up). Below
    ``min_rate_hz`` it is unusable at once; it is usable again after the rate has held
    at or above it for ``hold_s`` (hysteresis in time), and after any IMU timeout.
    """

    def __init__(self, min_rate_hz: float, hold_s: float) -> None:
        self.min_rate_hz = min_rate_hz
        self.hold_s = hold_s
        self.rate_hz: float | None = None
        """The last window's measured rate (None before the first window closes)."""
        self.usable = True
        self.changes = 0
        """How many times ``usable`` changed."""
        self._last_t_s = -math.inf
        self._window_start_s: float | None = None
        self._window_n = 0
        self._good_since_s: float | None = None

    def on_sample(self, t_s: float) -> None:
        """Count one IMU sample at ``t_s``."""
        if t_s <= self._last_t_s:
            return
        self._last_t_s = t_s
        start = self._window_start_s
        if start is None:
            self._window_start_s = t_s
            self._window_n = 0
            return
        self._window_n += 1
        if t_s - start < IMU_RATE_WINDOW_S:
            return
        rate = self._window_n / (t_s - start)
        self.rate_hz = rate
        self._window_start_s = t_s
        self._window_n = 0
        if rate < self.min_rate_hz:
            self._good_since_s = None
            self._set(False)
            return
        if self._good_since_s is None:
            self._good_since_s = start
        if not self.usable and t_s - self._good_since_s >= self.hold_s:
            self._set(True)

    def restarted(self) -> ImuRate:
        """A new measurement of the same stream for a navigation restarted from scratch
        (after a silence or a reboot: the sample clock may start again): its windows
        start afresh, and a stream last measured below ``min_rate_hz`` stays unusable
        until the rate has held for ``hold_s``. A restart does not make a slow stream
        fast: without this the blend carried a 1.3 Hz radio IMU after every silence
        until its first window closed, and its first predicted fixes were excluded as
        faults (copter_radio_realistic at 142.6 s)."""
        new = ImuRate(self.min_rate_hz, self.hold_s)
        new.rate_hz = self.rate_hz
        if self.rate_hz is not None and self.rate_hz < self.min_rate_hz:
            new.usable = False
        return new

    def timed_out(self) -> None:
        """No IMU sample for the timeout: unusable until the rate has held again."""
        self._window_start_s = None
        self._good_since_s = None
        self._set(False)

    def _set(self, usable: bool) -> None:
        if usable is not self.usable:
            self.usable = usable
            self.changes += 1
            log.info(
                "IMU %s for dead reckoning (%.1f Hz, minimum %.0f Hz)",
                "usable" if usable else "not usable",
                self.rate_hz if self.rate_hz is not None else float("nan"),
                self.min_rate_hz,
            )


class Navigators:
    """The primary navigator (the blend, if configured), the fallback, and the choice."""

    def __init__(
        self,
        kind: str,
        blend: BlendConfig,
        imu_timeout_s: float,
        min_imu_rate_hz: float = 20.0,
        imu_rate_hold_s: float = 5.0,
    ) -> None:
        """``kind`` is ``EngineConfig.navigator``; ``imu_timeout_s`` its IMU timeout,
        ``min_imu_rate_hz`` and ``imu_rate_hold_s`` the IMU's usability (:class:`ImuRate`)."""
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
        self.imu_rate = ImuRate(min_imu_rate_hz, imu_rate_hold_s)
        """The IMU's measured rate and usability."""
        self._restart_primary = False
        """The IMU was unusable: the primary restarts from the next fix."""
        self.switches = 0
        """How many times the carrying navigator changed."""

    def all(self) -> list[Navigator]:
        """Every navigator kept up to date (the primary first)."""
        return [self.fallback] if self.primary is None else [self.primary, self.fallback]

    def on_imu(self, sample: ImuSample) -> bool:
        """An IMU sample for the primary; False when there is none (no IMU navigator)."""
        primary = self.primary
        if primary is None:
            return False
        primary.on_imu(sample)
        self.imu_rate.on_sample(sample.t_s)
        self.last_imu_t_s = sample.t_s
        return True

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> bool:
        """An attitude sample for the primary; False when there is none."""
        primary = self.primary
        if primary is None:
            return False
        primary.on_attitude(sample, yaw_correction_rad)
        return True

    def hold_attitude(self, hold: bool) -> None:
        """Hold the autopilot's attitude out of the blend (its body rates carry the blend's),
        or take it again (:meth:`BlendNavigator.hold_attitude`)."""
        primary = self.primary
        if isinstance(primary, BlendNavigator) and primary.attitude_held is not hold:
            primary.hold_attitude(hold)

    def attitude_unaided(self, unaided: bool, *, tilt: bool = False) -> None:
        """A GNSS gap the autopilot shares begins (``True``) or ends: its attitude is
        modelled unaided through it, its tilt too when ``tilt``
        (:meth:`BlendNavigator.attitude_unaided`)."""
        primary = self.primary
        if isinstance(primary, BlendNavigator):
            primary.attitude_unaided(unaided, tilt=tilt)  # also after a restart or a hold released

    def select(self, now_s: float | None) -> None:
        """The blend carries the solution while it runs on a live, usable IMU stream."""
        primary = self.primary
        rate = self.imu_rate
        if (
            primary is not None
            and now_s is not None
            and now_s - self.last_imu_t_s > self._imu_timeout_s
            and self.last_imu_t_s > -math.inf
            and rate.usable
        ):
            rate.timed_out()
        if not rate.usable:
            self._restart_primary = True
        live = (
            primary is not None
            and primary.initialised
            and rate.usable
            and not self._restart_primary
            and now_s is not None
            and now_s - self.last_imu_t_s <= self._imu_timeout_s
        )
        chosen = primary if live and primary is not None else self.fallback
        if chosen is not self.navigator:
            log.info("navigator: %s", type(chosen).__name__)
            self.switches += 1
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
            if self._restart_primary and self.imu_rate.usable:
                # the IMU is usable again: what the blend integrated meanwhile is not
                # trusted; it restarts from this fix and carries from the next selection
                primary.reset()
                self._restart_primary = False
            primary.on_gnss(meas, gate=gate and primary.initialised)
        return update

    def force(self, meas: GnssMeasurement, rejected: GnssUpdate) -> GnssUpdate:
        """Fuse ``meas``, which the carrying navigator's gate just rejected (``rejected``),
        without the gate: the receiver's own evidence vouches for it, the prediction is
        what is off. That evidence is horizontal (GPS_RAW_INT has no vertical velocity):
        when the height alone fails its gate, ``rejected`` is returned unchanged."""
        if not vertical_within_gate(rejected):
            return rejected
        primary = self.primary
        if primary is not None and self.navigator is primary:
            backlog = self.backlog
            if backlog and backlog[-1][0] is meas:
                backlog[-1] = (meas, False)  # the fallback takes it as the primary did
            return primary.on_gnss(meas, gate=False)
        return self.fallback.on_gnss(meas, gate=False)

    def reinitialise(self, meas: GnssMeasurement) -> None:
        """Restart every navigator from the fix ``meas`` (taken without a gate)."""
        self.backlog.clear()
        self._backlog_overflowed = False
        if self.imu_rate.usable:
            self._restart_primary = False
        for nav in self.all():
            nav.reset()
            nav.on_gnss(meas, gate=False)

    def rebase(self, state: NavState, meas: GnssMeasurement) -> None:
        """Restart every navigator's position and velocity from ``state`` (``meas``: the
        same as a measurement): the blend keeps its attitude and biases
        (:meth:`BlendNavigator.rebase`), the others restart from ``meas``."""
        self.backlog.clear()
        self._backlog_overflowed = False
        for nav in self.all():
            if isinstance(nav, BlendNavigator) and nav.rebase(state):
                continue
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
