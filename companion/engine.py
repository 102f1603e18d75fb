"""The pure core's entry point: typed samples in, outputs out.

``Engine.handle(sample)`` is the only call a driver makes (the live service
and the tlog replay alike). It never opens a socket, reads a clock or imports
pymavlink: time is the autopilot's ``t_s`` carried by the samples, so the same
samples give the same outputs, bit for bit.

What it does with a sample:

* IMU and attitude go to the navigator (and attitude to the heading
  corrector); every timed sample advances the engine's clock ``now``.
* A GNSS fix is judged by the outage monitor (usable? stale? downgraded?),
  converted into the local NED frame and offered to the navigator, which gates
  it against its prediction; the verdict goes back to the monitor.
* Whenever ``now`` crosses a publication tick (``publish_rate_hz`` on the
  autopilot clock) the navigator's state is carried to ``now`` and published
  as a :class:`NavSolution` — also while GNSS is silent, then clocked by the
  IMU/attitude stream. Status values (``CMP_HACC`` ...) follow at
  ``status_rate_hz``.

The local NED frame is anchored at the first usable fix and re-anchored when
the solution is ``reanchor_distance_m`` from it.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from companion.integrity.coast import CoastConfig, InertialCoast
from companion.integrity.monitor import IntegrityConfig, IntegrityMonitor
from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.earth import gravity_ned_mps2
from companion.nav.frames import LocalFrame
from companion.nav.gnss import gnss_measurement
from companion.nav.heading import HeadingConfig, HeadingCorrector
from companion.nav.motion import SingerConfig, SingerNavigator
from companion.nav.navigator import (
    GnssMeasurement,
    Navigator,
    NavState,
    rotation_between_frames,
)
from companion.nav.outage import OUTAGE_MODES, OutageConfig, OutageMonitor
from companion.nav.passthrough import PassthroughConfig, PassthroughNavigator
from companion.nav.potential import (
    PotentialConfig,
    PotentialFilter,
    PotentialPrediction,
    combine_with_ins,
)
from companion.nav.rotations import wrap_2pi
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    FixType,
    GnssFix,
    HeadingCommand,
    ImuSample,
    LandedState,
    LandedStateSample,
    NamedValue,
    NavMode,
    NavSolution,
    Output,
    RebootEvent,
    Sample,
    VfrHudSample,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class EngineConfig:
    """Publication and frame handling of the engine."""

    publish_rate_hz: float = 10.0
    """GLOBAL_POSITION_INT / GPS_INPUT rate on the autopilot clock (5-10 Hz for GPS_INPUT)."""
    status_rate_hz: float = 1.0
    """Rate of the CMP_* NAMED_VALUE_FLOAT status values."""
    reanchor_distance_m: float = 20_000.0
    """Re-anchor the local NED frame when the solution is this far from its anchor."""
    navigator: str = "blend"
    """Which navigator carries the position: 'blend' (GNSS/INS, S1; with the pass-through
    taking over while no IMU stream arrives), 'singer' (S2's manoeuvre model, no IMU) or
    'passthrough' (GNSS with constant-velocity extrapolation)."""
    imu_timeout_s: float = 0.5
    """The blend carries the solution only while an IMU sample is at most this old."""
    primary_receiver: int = 0
    """The receiver fused normally; the other is fused only while this one is unusable
    (and is always the integrity monitor's independent solution)."""
    potential_bridge: bool = True
    """Without an IMU stream, carry the solution through GNSS gaps (BRIDGING) with the
    position-potential filter (S0) instead of the pass-through's constant velocity."""
    potential_combine: bool = False
    """With an IMU stream, publish through gaps the INS and potential predictions combined
    by their covariances (their shared last-fix error as cross-covariance) while the two
    agree (:func:`companion.nav.potential.combine_with_ins`). bench/potential.py part B,
    RTK-fixed flights: 0.66-0.99 of the better of the two alone, approaches and turning
    cruises; as a pseudo-measurement in the blend it was worse. But on the bundled
    cruise_gnss_loss flight (MEMS, a minute of turns) it is worse than the INS alone
    (mean 3.2 m against 2.9 m): off by default."""
    inertial_reference: bool = False
    """With the blend, keep free-inertial solutions coasting from staggered anchors
    (:mod:`companion.integrity.coast`, the ``[coast]`` block) as the integrity monitor's
    references: they do not contain the receivers' recent fixes, so a slow vertical ramp or
    a sub-metre dither shows against them even with one receiver (S3's separation set).
    Worth its cost (about 0.3 ms per fix) with a tactical IMU; a MEMS IMU drifts too fast
    to catch anything the innovation test misses (bench/integrity.py)."""
    potential_fix_test: bool = False
    """Test each fix of the fused receiver against the potential prediction's ellipsoid
    (S0) in the integrity monitor. Off by default: the prediction has no acceleration,
    so the test trips at manoeuvre onsets (turns, rotation) where the blend's innovation
    test, with the IMU, does not."""

    def __post_init__(self) -> None:
        if not 0.0 < self.publish_rate_hz <= 50.0:
            raise ValueError("publish_rate_hz must be in (0, 50]")
        if not 0.0 < self.status_rate_hz <= self.publish_rate_hz:
            raise ValueError("status_rate_hz must be in (0, publish_rate_hz]")
        if self.reanchor_distance_m < 1000.0:
            raise ValueError("reanchor_distance_m must be >= 1000")
        if self.navigator not in NAVIGATORS:
            raise ValueError(f"navigator must be one of {sorted(NAVIGATORS)}")
        if not 0.0 < self.imu_timeout_s <= 5.0:
            raise ValueError("imu_timeout_s must be in (0, 5]")
        if self.primary_receiver not in (0, 1):
            raise ValueError("primary_receiver must be 0 (GPS_RAW_INT) or 1 (GPS2_RAW)")


NAVIGATORS = ("blend", "singer", "passthrough")


@dataclass(slots=True)
class EngineStats:
    """Counters a driver prints in its summary."""

    gnss: Counter[str] = field(default_factory=Counter)
    alerts: Counter[str] = field(default_factory=Counter)
    solutions: int = 0
    reboots: int = 0
    reanchors: int = 0


class Engine:
    """Samples in, outputs out. See the module docstring."""

    def sample_counts(self) -> dict[str, int]:
        """Samples handled, by type name."""
        return {kind.__name__: n for kind, n in self._sample_counts.items()}

    def __init__(
        self,
        config: EngineConfig | None = None,
        outage: OutageConfig | None = None,
        heading: HeadingConfig | None = None,
        blend: BlendConfig | None = None,
        integrity: IntegrityConfig | None = None,
        potential: PotentialConfig | None = None,
        coast: CoastConfig | None = None,
    ) -> None:
        self.config = config or EngineConfig()
        self._outage_config = outage or OutageConfig()
        self._heading_config = heading or HeadingConfig()
        self._blend_config = blend or BlendConfig.for_grade("mems")
        self._integrity_config = integrity or IntegrityConfig()
        self._potential_config = potential or PotentialConfig()
        self._coast_config = coast or CoastConfig.for_grade("mems")
        self._combine_threshold = float(chi2.isf(self._potential_config.false_alarm_prob, 3))
        self.state_changes = 0
        """Incremented whenever :meth:`persistent_state` changes (drivers persist it)."""
        self._pending_state: dict[str, object] | None = None
        self._sample_counts: Counter[type] = Counter()
        self._publish_rate_hz = self.config.publish_rate_hz
        self.stats = EngineStats()
        self._handlers: dict[type, Callable[[object], list[Output]]] = {
            ImuSample: self._on_imu,  # type: ignore[dict-item]
            AttitudeSample: self._on_attitude,  # type: ignore[dict-item]
            GnssFix: self._on_gnss,  # type: ignore[dict-item]
            LandedStateSample: self._on_landed,  # type: ignore[dict-item]
            VfrHudSample: self._on_vfr_hud,  # type: ignore[dict-item]
            HeadingCommand: self._on_heading_command,  # type: ignore[dict-item]
            RebootEvent: self._on_reboot,  # type: ignore[dict-item]
        }
        self._reset()

    def _reset(self) -> None:
        kind = self.config.navigator
        self.fallback: Navigator = PassthroughNavigator(PassthroughConfig())
        self.primary: Navigator | None = None
        if kind == "blend":
            self.primary = BlendNavigator(self._blend_config)
        elif kind == "singer":
            self.fallback = SingerNavigator(SingerConfig())
        self.navigator: Navigator = self.fallback
        """The navigator carrying the solution now (the blend, or the fallback)."""
        self._fallback_backlog: deque[tuple[GnssMeasurement, bool]] = deque(
            maxlen=FALLBACK_BACKLOG_FIXES
        )
        """Fixes (and their gate flags) the fallback has not taken yet: while the blend
        carries the solution the fallback is fed when it is needed (it takes over, or the
        frame moves), not at every fix, where its result would be thrown away."""
        self._fallback_stale = False
        """The backlog overflowed: the fallback restarts from the fixes it holds."""
        self._last_imu_t_s = -math.inf
        self.monitor = OutageMonitor(self._outage_config)
        self.integrity = IntegrityMonitor(self._integrity_config)
        cfg = self.config
        self._potential_used = (
            cfg.potential_bridge or cfg.potential_combine or cfg.potential_fix_test
        )
        self.potential: PotentialFilter | None = None
        """S0's filter on the fused fixes, when one of its uses is configured: the no-IMU
        bridge, a second opinion beside the INS through gaps, the ellipsoid test of a fix.
        Fed at every fix only for the fix test; for the bridges alone it is built when a
        gap starts from the last ``window_s`` of fused fixes (``_recent_fixes``): the
        same state, without fitting alpha and G every few seconds of flight for nothing."""
        self._recent_fixes: deque[GnssMeasurement] = deque()
        self._potential_gap = False
        """The potential filter is ready for this gap (cleared by the next fused fix)."""
        self._potential_disagrees = False
        """The potential and INS predictions failed their consistency test in this gap."""
        self.coast: InertialCoast | None = None
        """The free-inertial references (with the blend, once the frame exists)."""
        self._landed: LandedState | None = None
        self._airborne = False
        self._speed_mps: float | None = None
        """Ground speed of the last published state (the stale-fix test's motion)."""
        self._rx_last_usable_t_s: dict[int, float] = {}
        self.frame: LocalFrame | None = None
        self.now_s: float | None = None
        self._publish_tick = -1
        self._next_monitor_tick_s = -math.inf
        self._status_tick = -1
        self._last_fused_fix: GnssFix | None = None
        self._yaw_rad: float | None = None
        self._satellites = 0
        self.heading = HeadingCorrector(self._heading_config)

    # ------------------------------------------------------------------ entry point

    def handle(self, sample: Sample) -> list[Output]:
        """Take one sample; return what to publish (possibly nothing)."""
        kind = type(sample)
        self._sample_counts[kind] += 1
        if self._pending_state is not None:
            self._restore_now(sample.t_s)
        handler = self._handlers.get(kind)
        outputs = handler(sample) if handler is not None else []
        t_s = sample.t_s
        now = self.now_s
        if now is None or t_s > now:
            self.now_s = now = t_s
        if self.monitor.last_fused_t_s is not None:
            # hot path (every IMU sample): the outage clock is ticked at most every
            # _TICK_S, publication when the integer period index advances
            if now >= self._next_monitor_tick_s:
                self._next_monitor_tick_s = now + _TICK_S
                outputs += self.monitor.tick(now)
            tick = math.floor(now * self._publish_rate_hz + 1e-6)
            if tick > self._publish_tick:
                self._publish_tick = tick
                outputs += self._publish(now)
        if not outputs:
            return outputs
        for out in outputs:
            if isinstance(out, Alert):
                self.stats.alerts[out.code.value] += 1
                if out.code in _HEADING_CODES:
                    self.state_changes += 1
                if out.code is AlertCode.HDG_APPLIED:
                    self._heading_applied()
        return outputs

    # ------------------------------------------------------------------ handlers

    def _on_imu(self, sample: ImuSample) -> list[Output]:
        if self.primary is not None:
            self.primary.on_imu(sample)
            self._last_imu_t_s = sample.t_s
            if self.coast is not None:
                self.coast.on_imu(sample)
        return []

    def _on_attitude(self, sample: AttitudeSample) -> list[Output]:
        self._yaw_rad = sample.yaw_rad
        if not self._airborne:  # S4 runs on the ground before take-off
            self.heading.on_attitude(sample)
        if self.primary is not None:
            self.primary.on_attitude(sample, self.heading.correction_rad)
            if self.coast is not None:
                self.coast.on_attitude(sample, self.heading.correction_rad)
        return []

    def _on_landed(self, sample: LandedStateSample) -> list[Output]:
        state = sample.landed_state
        self._landed = state
        if state in (LandedState.IN_AIR, LandedState.LANDING):
            self._airborne = True
        on_ground = None if state is LandedState.UNDEFINED else state is LandedState.ON_GROUND
        self.heading.on_landed_state(on_ground)
        return []

    def _on_vfr_hud(self, sample: VfrHudSample) -> list[Output]:
        self.heading.on_vfr_hud(sample)
        return []

    def _on_heading_command(self, sample: HeadingCommand) -> list[Output]:
        return self.heading.on_command(sample)

    def _heading_applied(self) -> None:
        """The navigators restart their heading error from the applied correction."""
        applied = self.heading.applied
        if applied is None:
            return
        sigma_rad = max(applied.eps_rad / self._heading_config.z_score, 1e-6)
        for nav in self._navigators():
            nav.reset_heading(sigma_rad)

    # ------------------------------------------------------------------ persistence

    def persistent_state(self) -> dict[str, object]:
        """What must survive a restart of the service during a flight (JSON-safe):
        the heading correction, tied to the autopilot clock it was made on."""
        return {"t_s": self.now_s, "heading": self.heading.to_state()}

    def restore(self, state: dict[str, object]) -> None:
        """Restore :meth:`persistent_state` once the first sample shows the same
        autopilot boot (its clock not behind the saved time); otherwise drop it."""
        self._pending_state = state

    def _restore_now(self, t_s: float) -> None:
        state, self._pending_state = self._pending_state, None
        if state is None:
            return
        saved_t = state.get("t_s")
        if not isinstance(saved_t, int | float) or t_s < saved_t:
            log.info("saved state is from an earlier autopilot boot: not restored")
            return
        heading = state.get("heading")
        if not isinstance(heading, dict):
            log.warning("saved state has no heading block: not restored")
            return
        try:
            self.heading = HeadingCorrector.from_state(self._heading_config, heading)
        except ValueError as exc:
            log.warning("saved heading state rejected: %s", exc)
            return
        log.info("heading correction restored: %.3f deg", math.degrees(self.heading.correction_rad))

    def _on_reboot(self, sample: RebootEvent) -> list[Output]:
        log.warning(
            "autopilot reboot (clock %.1f s -> %.1f s): navigation restarts",
            sample.previous_t_s,
            sample.t_s,
        )
        self.stats.reboots += 1
        self._reset()
        return []

    def _on_gnss(self, fix: GnssFix) -> list[Output]:
        # S4 corrects the heading during the taxi before take-off; once airborne the
        # correction (applied or not) stands for the rest of the flight
        outputs: list[Output] = [] if self._airborne else self.heading.on_gnss(fix)
        self._select_navigator()
        verdict = self.monitor.assess(fix, self._speed_mps)
        outputs += verdict.alerts
        if not verdict.usable:
            self.stats.gnss[verdict.reason] += 1
            return outputs
        if self.frame is None:
            self._anchor(LocalFrame(fix.lat_rad, fix.lon_rad, fix.alt_msl_m))
        if self.frame is None:  # _anchor sets it; keeps mypy honest
            raise ValueError("no local frame after anchoring")
        meas = gnss_measurement(fix, self.frame)
        # the references are for flight: on the ground, before S4 has corrected it, the
        # autopilot's heading can be degrees off and taxi turns turn that into metres
        refs = (
            self.coast.references(meas.t_s)
            if self.coast is not None and not self._on_ground()
            else None
        )
        if not self._fuse_receiver(fix):
            # the other receiver: the integrity monitor's independent solution only
            self.stats.gnss[f"rx{fix.receiver_id}_monitored"] += 1
            outputs += self.integrity.on_fix(fix, meas, None, references=refs)
            return outputs
        if self.integrity.exclude(fix.receiver_id):
            self.stats.gnss["excluded"] += 1
            outputs += self.integrity.on_fix(fix, meas, None, references=refs)
            return outputs
        if verdict.reinitialise:
            self._fallback_backlog.clear()
            self._fallback_stale = False
            for nav in self._navigators():
                nav.reset()
                nav.on_gnss(meas, gate=False)
            self._recent_fixes.clear()
            if self.potential is not None:
                self.potential.reset()
            self._potential_add(meas)
            outputs += self.monitor.reinitialised(fix.t_s)
            self.stats.gnss["reinitialised"] += 1
            self._last_fused_fix = fix
            return outputs
        predicted = self._potential_reference(meas.t_s)
        primary = self.primary
        if primary is not None and self.navigator is primary:
            self._defer_to_fallback(meas, verdict.gate)
            update = primary.on_gnss(meas, gate=verdict.gate)
        else:
            self._sync_fallback()
            update = self.fallback.on_gnss(meas, gate=verdict.gate)
            if primary is not None:
                primary.on_gnss(meas, gate=verdict.gate and primary.initialised)
        if update.fused:
            self.stats.gnss["fused"] += 1
            self._last_fused_fix = fix
            self._satellites = fix.satellites or 0
            self._potential_add(meas)
        else:
            self.stats.gnss["gate_rejected" if update.reason == "gate" else update.reason] += 1
        # after a gap the navigator's prediction, not the receiver, is what is uncertain: a
        # failed innovation then is the outage logic's (gate, reacquire, re-initialise), and
        # must not exclude the receiver (which would stop the re-initialisation forever)
        bridged = verdict.gate and self.monitor.mode in OUTAGE_MODES
        outputs += self.integrity.on_fix(
            fix, meas, None if bridged else update, predicted=predicted, references=refs
        )
        if update.fused or update.reason == "gate":
            outputs += self.monitor.gate_result(fix.t_s, update.fused)
        return outputs

    def _navigators(self) -> list[Navigator]:
        return [self.fallback] if self.primary is None else [self.primary, self.fallback]

    def _select_navigator(self) -> None:
        """The blend carries the solution while it runs on a live IMU stream."""
        primary = self.primary
        live = (
            primary is not None
            and primary.initialised
            and self.now_s is not None
            and self.now_s - self._last_imu_t_s <= self.config.imu_timeout_s
        )
        chosen = primary if live and primary is not None else self.fallback
        if chosen is not self.navigator:
            log.info("navigator: %s", type(chosen).__name__)
            if chosen is self.fallback:
                self._sync_fallback()
            self.navigator = chosen

    def _defer_to_fallback(self, meas: GnssMeasurement, gate: bool) -> None:
        """Keep a fix for the fallback, which takes it when it is next needed."""
        backlog = self._fallback_backlog
        if len(backlog) == backlog.maxlen:
            self._fallback_stale = True
        backlog.append((meas, gate))

    def _sync_fallback(self) -> None:
        """Give the fallback the fixes it has not taken, in order, as it would have taken
        them one by one (restarted from the oldest held when some were dropped: the
        pass-through's state depends on the last fix and, through its vertical-velocity
        average, on earlier ones with weights (1 - k)^n: below 1e-90 after a full backlog
        with the default gain k = 0.3)."""
        backlog = self._fallback_backlog
        if not backlog:
            return
        fallback = self.fallback
        if self._fallback_stale:
            fallback.reset()
            self._fallback_stale = False
        for meas, gate in backlog:
            fallback.on_gnss(meas, gate=gate)
        backlog.clear()

    def _fuse_receiver(self, fix: GnssFix) -> bool:
        """Fuse the primary receiver; the other only while the primary is unusable."""
        self._rx_last_usable_t_s[fix.receiver_id] = fix.t_s
        primary = self.config.primary_receiver
        if fix.receiver_id == primary:
            return True
        last_primary = self._rx_last_usable_t_s.get(primary, -math.inf)
        primary_down = (
            fix.t_s - last_primary > self._outage_config.gnss_timeout_s
            or self.integrity.exclude(primary)
        )
        return primary_down

    def _potential_add(self, meas: GnssMeasurement) -> None:
        """A fused fix becomes a source of the potential field (refitted when due)."""
        self._potential_gap = False
        if not self._potential_used:
            return
        if self.config.potential_fix_test:
            if self.potential is None:
                self.potential = PotentialFilter(self._potential_config)
            self.potential.add_fix(meas.t_s, meas.pos_ned_m, meas.pos_var_ned_m2, meas.vel_ned_mps)
            return
        recent = self._recent_fixes
        recent.append(meas)
        horizon_s = self._potential_config.window_s
        while recent and meas.t_s - recent[0].t_s > horizon_s:
            recent.popleft()

    def _potential_for_gap(self) -> PotentialFilter | None:
        """The potential filter at the start of a gap, alpha and G refitted on the fixes
        just before it (built from the recent fixes unless it is fed at every fix)."""
        if not self.config.potential_fix_test and self._recent_fixes:
            pot = PotentialFilter(self._potential_config)
            for m in self._recent_fixes:
                pot.add_fix(m.t_s, m.pos_ned_m, m.pos_var_ned_m2, m.vel_ned_mps)
            self.potential = pot
        if self.potential is not None:
            self.potential.refit(force=True)
        return self.potential

    def _potential_reference(self, t_s: float) -> NavState | None:
        """The potential prediction at a new fix's time, for the monitor's ellipsoid test
        (None until its covariance is calibrated by a first fit)."""
        pot = self.potential
        if pot is None or not self.config.potential_fix_test:
            return None
        if not pot.calibrated or pot.t_last_s is None:
            return None
        if t_s <= pot.t_last_s:
            return None
        return _potential_state(pot.predict(t_s))

    def _bridge(self, state: NavState, t_s: float) -> NavState:
        """The published state through a GNSS gap: the potential filter's without an IMU,
        optionally combined with the INS's with one (EngineConfig.potential_*)."""
        if self.monitor.mode not in (NavMode.BRIDGING, NavMode.LOST):
            return state
        no_imu = self.navigator is self.fallback
        if not (self.config.potential_bridge if no_imu else self.config.potential_combine):
            return state
        if not self._potential_gap:
            self._potential_gap = True
            self._potential_disagrees = False
            self._potential_for_gap()
        pot = self.potential
        if pot is None or pot.t_last_s is None or t_s < pot.t_last_s:
            return state
        pred = pot.predict(t_s)
        if no_imu:
            return _potential_state(pred, state.yaw_rad)
        if self._potential_disagrees:
            return state  # once they disagreed in this gap, the INS alone to its end
        pos, cov, chi2_ = combine_with_ins(
            state.pos_ned_m, state.pos_cov_ned_m2, pred, self._combine_threshold
        )
        if chi2_ > self._combine_threshold:
            self._potential_disagrees = True
            log.info(
                "t=%.2f s: potential prediction disagrees with the INS (chi2 %.1f)", t_s, chi2_
            )
            return state
        return replace(state, pos_ned_m=pos, pos_cov_ned_m2=cov)

    def _anchor(self, frame: LocalFrame) -> None:
        self.frame = frame
        for nav in self._navigators():
            nav.shift_frame(frame, frame)  # the blend takes its gravity model from the frame
        if self.primary is not None and self.config.inertial_reference:
            gravity = gravity_ned_mps2(frame.lat0_rad, frame.alt0_m)
            self.coast = InertialCoast(self._coast_config, gravity)

    def _on_ground(self) -> bool:
        """Not yet airborne by the autopilot's landed state (False when it sends none)."""
        return not self._airborne and self._landed not in (None, LandedState.UNDEFINED)

    def _anchor_coast(self) -> None:
        """Re-anchor a due coasting slot from the blend at its newest IMU time, only while
        the blend fuses trusted GNSS (never from a solution a fault may have pulled)."""
        coast, blend = self.coast, self.primary
        if coast is None or not isinstance(blend, BlendNavigator) or self.navigator is not blend:
            return
        if (
            self._on_ground()
            or self.monitor.mode is not NavMode.NORMAL
            or self.integrity.fault_detected
        ):
            return
        t_s = blend.imu_t_s
        if not coast.anchor_due(t_s):
            return
        state = blend.predict(t_s)
        if state is not None:
            bias_b_mps2, _ = blend.biases
            coast.anchor(state, bias_b_mps2, blend.covariance[9:12, 9:12])

    # ------------------------------------------------------------------ publication

    def _state_now(self, t_s: float) -> NavState | None:
        if not self.navigator.initialised:
            return None
        t_s = max(t_s, self.now_s or t_s)
        state = self.navigator.predict(t_s)
        return None if state is None else self._bridge(state, t_s)

    def _publish(self, now_s: float) -> list[Output]:
        # the solution is carried to the next whole millisecond: GLOBAL_POSITION_INT's
        # time_boot_ms is what a receiver aligns it by
        t_s = math.ceil(now_s * 1000.0 - 1e-6) / 1000.0
        self._select_navigator()
        state = self._state_now(t_s)
        if state is None or self.frame is None:
            return []
        self._speed_mps = float(np.hypot(state.vel_ned_mps[0], state.vel_ned_mps[1]))
        self._anchor_coast()
        if self._maybe_reanchor(state):
            state = self._state_now(t_s)
            if state is None:  # shifting a state never uninitialises it; keeps mypy honest
                return []
        lat, lon, alt = self.frame.ned_to_lla(state.pos_ned_m)
        solution = NavSolution(
            t_s=t_s,
            lat_rad=lat,
            lon_rad=lon,
            alt_msl_m=alt,
            vel_ned_mps=state.vel_ned_mps,
            pos_cov_ned_m2=state.pos_cov_ned_m2,
            vel_cov_ned_m2ps2=state.vel_cov_ned_m2ps2,
            yaw_rad=self._published_yaw(state),
            mode=self.monitor.mode,
            fix_type=self._honest_fix_type(),
            satellites=self._satellites,
        )
        outputs: list[Output] = list(self.integrity.on_solution(solution, self._landed))
        if not self.integrity.integrity_ok:
            solution = _integrity_lost(solution, self.integrity.accuracy_floor_m())
        self.stats.solutions += 1
        outputs.insert(0, solution)
        status_tick = _tick(t_s, self.config.status_rate_hz)
        if status_tick > self._status_tick:
            self._status_tick = status_tick
            outputs += [
                NamedValue(t_s, "CMP_HACC", solution.h_acc_m),
                NamedValue(t_s, "CMP_VACC", solution.v_acc_m),
                NamedValue(t_s, "CMP_OUTG", self.monitor.outage_s(t_s)),
                *(self.potential.outputs(t_s) if self.potential is not None else []),
            ]
        return outputs

    def _published_yaw(self, state: NavState) -> float | None:
        if state.yaw_rad is not None:
            return wrap_2pi(state.yaw_rad)
        if self._yaw_rad is not None:
            return wrap_2pi(self.heading.corrected_yaw_rad(self._yaw_rad))
        return None

    def _honest_fix_type(self) -> FixType:
        mode = self.monitor.mode
        if mode in (NavMode.LOST, NavMode.INIT) or self._last_fused_fix is None:
            return FixType.NO_FIX
        if mode in (NavMode.BRIDGING, NavMode.REACQUIRING):
            return FixType.FIX_3D
        return FixType(min(int(self._last_fused_fix.fix_type), int(FixType.RTK_FIXED)))

    def _maybe_reanchor(self, state: NavState) -> bool:
        """Re-anchor the frame at the solution when it is far from the anchor; True if it
        did (states computed before are then in the old frame)."""
        if self.frame is None or self.frame.distance_from_anchor_m(state.pos_ned_m) < (
            self.config.reanchor_distance_m
        ):
            return False
        lat, lon, alt = self.frame.ned_to_lla(state.pos_ned_m)
        new = LocalFrame(lat, lon, alt)
        self._sync_fallback()  # the fixes it has not taken are in the old frame
        for nav in self._navigators():
            nav.shift_frame(self.frame, new)
        self.integrity.shift_frame(self.frame, new)
        if self.coast is not None:
            offset = new.lla_to_ned(self.frame.lat0_rad, self.frame.lon0_rad, self.frame.alt0_m)
            self.coast.shift_frame(rotation_between_frames(self.frame, new), offset)
        self._recent_fixes.clear()
        if self.potential is not None:
            self.potential.reset()  # its window of fixes is in the old frame: refills in seconds
        self.frame = new
        self.stats.reanchors += 1
        log.info("local frame re-anchored at %.6f, %.6f", math.degrees(lat), math.degrees(lon))
        return True


def _potential_state(pred: PotentialPrediction, yaw_rad: float | None = None) -> NavState:
    return NavState(
        pred.t_s, pred.pos_ned_m, pred.vel_ned_mps, pred.cov_ned_m2, pred.vel_cov_ned_m2ps2, yaw_rad
    )


def _integrity_lost(solution: NavSolution, floor_m: tuple[float, float]) -> NavSolution:
    """The solution as published while integrity is lost: no fix, accuracies at least
    the monitor's floor (the size of the unexplained disagreement)."""
    cov = solution.pos_cov_ned_m2.copy()
    h_floor, v_floor = floor_m
    for axis, floor in ((0, h_floor), (1, h_floor), (2, v_floor)):
        cov[axis, axis] = max(cov[axis, axis], floor**2)
    return replace(solution, fix_type=FixType.NO_FIX, pos_cov_ned_m2=cov)


FALLBACK_BACKLOG_FIXES = 600
"""Fixes held for the fallback while the blend runs (a minute of a 10 Hz receiver)."""

_TICK_S = 0.05
"""Outage-clock resolution: GNSS_LOST is raised within this of its timeout."""

_HEADING_CODES = frozenset({AlertCode.HDG_READY, AlertCode.HDG_APPLIED, AlertCode.HDG_REJECT})


def _tick(t_s: float, rate_hz: float) -> int:
    """Index of the publication period containing ``t_s`` (robust to 0.1 not being binary)."""
    return math.floor(t_s * rate_hz + 1e-6)
