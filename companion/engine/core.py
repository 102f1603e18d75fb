"""The pure core's entry point: typed samples in, outputs out.

``Engine.handle(sample)`` is the only call a driver makes (the live service
and the tlog replay alike). It never opens a socket, reads a clock or imports
pymavlink: time is the autopilot's ``t_s`` carried by the samples, so the same
samples give the same outputs, bit for bit.

What it does with a sample:

* IMU and attitude go to the navigator (and attitude to the heading
  corrector); every timed sample advances the engine's clock ``now_s``.
* A GNSS fix is judged by the outage monitor (usable? stale? downgraded?),
  converted into the local NED frame and offered to the navigator, which gates
  it against its prediction; the verdict goes back to the outage monitor, the
  fix and the navigator's verdict to the integrity monitor.
* A raw receiver's carrier-phase solution (:class:`~companion.types.RawSolution`) is
  kept; while its own FIS-RAIM trusts it, it goes to the integrity monitor with each
  fix as the reference ``ref:tdprp`` of the separation tests. Its time is mapped from
  GPS time at the edge: it does not move the engine's clock.
* A :class:`~companion.types.GnssSignalReport` (the receiver's own jamming and spoofing
  flags, the raw link's signal tests) goes to the signal monitor
  (:mod:`companion.integrity.signal`: ``JAM``, the spoofing evidence), which also fills
  the published integrity report's jamming and spoofing states; it moves no clock.
* As soon as a fix has been fused (``publish_on_fix``), the navigator's state is
  carried to ``now_s`` and published as a :class:`NavSolution`
  (:mod:`companion.engine.publish`): the solution with that fix in it leaves at once,
  not at the next tick. Publications are at least ``min_publish_interval_s`` apart
  (ArduPilot's EKF drops a GPS message closer than 70 ms to the last one it took);
  while no fix is fused (GNSS silent, rejected, or a receiver slower than
  ``publish_rate_hz``) every ``1/publish_rate_hz``, clocked by the IMU/attitude
  stream, except that a fix expected soon is waited for half its interval (at most
  :data:`MAX_HOLD_S` after the last publication). Without
  ``publish_on_fix``, whenever ``now_s`` crosses a tick of ``publish_rate_hz``.

Its collaborators: :mod:`companion.engine.navigators` (which navigator carries
the solution), :mod:`companion.engine.bridge` (the potential filter through
gaps), :mod:`companion.engine.publish` (what a publication tick publishes).

The local NED frame is anchored at the first usable fix and re-anchored when
the solution is ``reanchor_distance_m`` from it. docs/architecture.md shows
where the engine sits between the drivers and the estimators.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from companion.engine.bridge import GAP_MODES, PotentialBridge
from companion.engine.bridge_choice import BridgeEvidence, inertial_accel_sigma_mps2
from companion.engine.config import EngineConfig
from companion.engine.navigators import Navigators
from companion.engine.publish import Publisher, publication_time_s, tick
from companion.engine.self_change import NoiseWatch, reseed
from companion.engine.silence import StreamWatch
from companion.engine.tilt_aiding import TiltAiding
from companion.integrity.coast import CoastConfig, InertialCoast
from companion.integrity.monitor import IntegrityConfig, IntegrityMonitor
from companion.integrity.signal import SignalMonitor
from companion.integrity.spoof import SpoofConfig
from companion.nav.baro import BaroConfig, BaroHeight, BaroReference
from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.earth import gravity_ned_mps2
from companion.nav.fix_rate import FixRhythm
from companion.nav.frames import LocalFrame, rotation_between_frames
from companion.nav.gnss import gnss_measurement
from companion.nav.grades import IMU_GRADES
from companion.nav.heading import HeadingConfig, HeadingCorrector, HeadingStatus
from companion.nav.imu_check import ImuNoiseCheck
from companion.nav.imu_innovations import ImuInnovationCheck, ImuInnovationConfig
from companion.nav.navigator import AnchoredState, GnssMeasurement, GnssUpdate, NavState
from companion.nav.outage import OUTAGE_MODES, OutageConfig, OutageMonitor
from companion.nav.potential import PotentialConfig
from companion.nav.vertical_prior import VerticalPrior
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    AutopilotSolution,
    BaroSample,
    FixType,
    GnssFix,
    GnssSignalReport,
    HeadingCommand,
    HeartbeatSample,
    ImuSample,
    IntegrityReport,
    LandedState,
    LandedStateSample,
    NavMode,
    NavSolution,
    Output,
    RawSolution,
    RebootEvent,
    Sample,
    Severity,
    VfrHudSample,
)

log = logging.getLogger(__name__)

OUTAGE_TICK_S = 0.05
"""Outage-clock resolution (s): GNSS_LOST is raised within this of its timeout."""
DUE_EPS_S = 1e-6
""":meth:`Engine.next_due_s` is this after a strict timeout (``> gnss_timeout_s``)."""
MAX_HOLD_S = 0.2
"""With ``publish_on_fix``, the longest wait for the next fix before a publication
without one (s): ArduPilot asks for GPS at 5 Hz at least (AP_GPS's GPS_MAX_DELTA_MS is
200 ms and a 45 ms margin)."""
LATE_FIX_INTERVALS = 0.5
"""... and how late (in fix intervals) an expected fix is waited for before it."""
RESET_ALERT_CHI2 = float(chi2.isf(1e-3, 2))
"""A reset of the navigator to a receiver is alerted only when the fix is beyond this
squared Mahalanobis distance (2 dof, false-alarm probability 1e-3: 13.8) from the
solution, their covariances combined: within it the solution had said it could be that
far off (:meth:`Engine._within_bound`)."""
_DATA_KINDS = frozenset({ImuSample, AttitudeSample, GnssFix})
"""Samples whose absence for ``silence_timeout_s`` is a silence (:mod:`.silence`)."""

_HEADING_CODES = frozenset(
    {
        AlertCode.HDG_READY,
        AlertCode.HDG_APPLIED,
        AlertCode.HDG_REJECT,
        AlertCode.HDG_ACCUM,
        AlertCode.HDG_IDLE,
        AlertCode.HDG_UNDONE,
    }
)
"""Alerts that change :meth:`Engine.persistent_state`."""

LIVE_KEYS: dict[str, frozenset[str]] = {
    "engine": frozenset(
        {
            "publish_rate_hz",
            "publish_on_fix",
            "min_publish_interval_s",
            "status_rate_hz",
            "reanchor_distance_m",
            "primary_receiver",
        }
    ),
    "outage": frozenset(f.name for f in dataclasses.fields(OutageConfig)),
    "heading": frozenset({"auto_apply", "publish_period_s"}),
    "integrity": frozenset(
        {"approach_category", "category_upgrade_dwell_s", "integrity_restore_dwell_s"}
    ),
}
"""The configuration keys :meth:`Engine.reconfigure` applies to the running estimators,
by block: those read where they are used (never turned into state when an estimator
is built). The outage monitor reads all of its keys so; the publication and status
clocks are re-based on the new rate. Every other key of the engine's blocks is built
into an estimator's state and changes only with a new engine (a restart)."""


@dataclass(slots=True)
class EngineStats:
    """Counters a driver prints in its summary."""

    gnss: Counter[str] = field(default_factory=Counter)
    alerts: Counter[str] = field(default_factory=Counter)
    solutions: int = 0
    reboots: int = 0
    reanchors: int = 0
    silences: int = 0
    """Silences ended by data (each restarted the navigation)."""


def _position_within_bound(update: GnssUpdate) -> bool:
    """Is the horizontal position innovation of ``update`` inside :data:`RESET_ALERT_CHI2`
    of its covariance?"""
    y = update.innovation[:2]
    cov = update.innovation_cov[:2, :2]
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(cov))):
        return False
    try:
        return float(y @ np.linalg.solve(cov, y)) <= RESET_ALERT_CHI2
    except np.linalg.LinAlgError:
        return False


class Engine:
    """Samples in, outputs out. See the module docstring."""

    def __init__(
        self,
        config: EngineConfig | None = None,
        outage: OutageConfig | None = None,
        heading: HeadingConfig | None = None,
        blend: BlendConfig | None = None,
        integrity: IntegrityConfig | None = None,
        potential: PotentialConfig | None = None,
        coast: CoastConfig | None = None,
        baro: BaroConfig | None = None,
        imu_innovations: ImuInnovationConfig | None = None,
        spoof: SpoofConfig | None = None,
    ) -> None:
        self.config = config or EngineConfig()
        self._spoof_config = spoof or SpoofConfig()
        self._outage_config = outage or OutageConfig()
        self._heading_config = heading or HeadingConfig()
        self._blend_config = blend or BlendConfig.for_grade("mems")
        self._integrity_config = integrity or IntegrityConfig()
        self._potential_config = potential or PotentialConfig()
        self._coast_config = coast or CoastConfig.for_grade("mems")
        self._baro_config = baro or BaroConfig()
        self._imu_innovation_config = imu_innovations or ImuInnovationConfig()
        self.imu_innovations: ImuInnovationCheck | None = None
        """The blend's GNSS innovations against the configured grade (None: nothing wider
        to fall back to; made at each boot by :meth:`_reset`)."""
        self.state_changes = 0
        """Incremented whenever :meth:`persistent_state` changes (drivers persist it)."""
        self.autopilot_fuses_output = False
        """The autopilot may fuse what we publish (set by the pipeline from its parameters:
        a GPS of type MAV taking our GPS_INPUT). With ``gap_attitude = "auto"`` the blend's
        attitude is then carried by the autopilot's body rates through a GNSS gap, not
        taken from its attitude (:meth:`BlendNavigator.hold_attitude`), and the solution is
        withdrawn from it past ``gap_feed_max_h_acc_m``."""
        self._feed_withdrawn = False
        """This gap's solutions go to the autopilot as "no fix" (``gap_feed_max_h_acc_m``)."""
        self._pending_state: dict[str, object] | None = None
        self._grade_widened = False
        """The IMU's measured noise exceeded its configured grade: the references are off
        for good (:meth:`_widen_grade`)."""
        self._sample_counts: Counter[type] = Counter()
        self._rhythm = FixRhythm()
        """The link's rhythm of fixes (slow or not): the link's, kept across restarts."""
        self._publish_rate_hz = self.config.publish_rate_hz
        self.stats = EngineStats()
        self.signal = SignalMonitor()
        """Signal-level interference: JAM, and each receiver's spoofing evidence
        (:mod:`companion.integrity.signal`); kept across autopilot reboots."""
        self._handlers: dict[type, Callable[[object], list[Output]]] = {
            ImuSample: self._on_imu,  # type: ignore[dict-item]
            AttitudeSample: self._on_attitude,  # type: ignore[dict-item]
            BaroSample: self._on_baro,  # type: ignore[dict-item]
            GnssFix: self._on_gnss,  # type: ignore[dict-item]
            LandedStateSample: self._on_landed,  # type: ignore[dict-item]
            VfrHudSample: self._on_vfr_hud,  # type: ignore[dict-item]
            HeadingCommand: self._on_heading_command,  # type: ignore[dict-item]
            RebootEvent: self._on_reboot,  # type: ignore[dict-item]
            AutopilotSolution: self._on_autopilot_solution,  # type: ignore[dict-item]
            HeartbeatSample: self._on_heartbeat,  # type: ignore[dict-item]
        }
        self._reset()

    def sample_counts(self) -> dict[str, int]:
        """Samples handled, by type name."""
        return {kind.__name__: n for kind, n in self._sample_counts.items()}

    def _reset(self) -> None:
        """Everything of one autopilot boot, from scratch (at start and after a reboot)."""
        cfg = self.config
        self.integrity = IntegrityMonitor(self._integrity_config, self._spoof_config)
        self.bridge_evidence = BridgeEvidence(inertial_accel_sigma_mps2(self._blend_config))
        """Probes of the inertial bridge against constant velocity (:mod:`.bridge_choice`)."""
        self._restart_navigation()
        watch = StreamWatch(
            cfg.silence_timeout_s,
            cfg.no_gnss_alert_s,
            cfg.no_gnss_repeat_s,
            cfg.silence_intervals,
            cfg.silence_timeout_max_s,
        )
        previous: StreamWatch | None = getattr(self, "watch", None)
        if previous is not None:
            watch.keep_pauses(previous)  # the link's pauses survive an autopilot reboot
        self.watch = watch
        """Silence of the autopilot's data and no GNSS at all (:mod:`.silence`)."""
        self._landed: LandedState | None = None
        self.now_s: float | None = None
        self._publish_tick = -1
        self._last_publish_s = -math.inf
        """Autopilot time of the last publication (``publish_on_fix``)."""
        self._publish_due_s = -math.inf
        """When the next publication without a new fix is due (``publish_on_fix``)."""
        self._next_fix_s = -math.inf
        """When the next fix is expected (autopilot clock, ``publish_on_fix``)."""
        self._yaw_rad: float | None = None
        """The autopilot's latest heading (ATTITUDE), uncorrected."""
        self._attitude: AttitudeSample | None = None
        """The latest attitude sample (taken again when the heading correction changes)."""
        self.tilt_aiding = TiltAiding()
        """Whether the autopilot's tilt is aided without GNSS (:mod:`.tilt_aiding`)."""
        self.heading = HeadingCorrector(self._heading_config)
        self.baro = BaroHeight(self._baro_config, stats=self.integrity.stats)
        """The barometer's height, calibrated against trusted GNSS (:mod:`companion.nav.baro`);
        its rejections count in the integrity monitor's ``stats``."""
        self._baro_source: tuple[str, int] | None = None
        self._engine_baro_in_blend = self.config.baro_in_blend
        self.imu_check = self._imu_check()
        """The IMU's measured noise against its configured grade (None: nothing wider to
        fall back to)."""
        self.imu_innovations = (
            ImuInnovationCheck(self._imu_innovation_config)
            if self.config.imu_grade_check and self._grade_narrower_than_mems()
            else None
        )
        self._noise_watch = NoiseWatch(self._imu_innovation_config.min_ratio)
        self._imu_source: tuple[str, int] | None = None
        self._raw: RawSolution | None = None
        """The raw receiver's latest carrier-phase solution (a redundant solution)."""

    def _restart_navigation(self) -> None:
        """The navigation from scratch, started again by the next usable fix (at start,
        after a reboot, after a silence): navigators, outage monitor, integrity monitor
        (its counters kept), bridge, publisher, local frame and inertial references. The
        heading correction, the landed state and the clocks are the caller's."""
        cfg = self.config
        old = getattr(self, "navigators", None)
        self.navigators = Navigators(
            cfg.navigator,
            self._blend_config,
            cfg.imu_timeout_s,
            cfg.min_imu_rate_hz,
            cfg.imu_rate_hold_s,
        )
        if old is not None:
            self.navigators.imu_rate = old.imu_rate.restarted()  # a slow IMU stays slow
        if old is not None and isinstance(old.primary, BlendNavigator):
            new = self.navigators.primary
            if isinstance(new, BlendNavigator):
                new.adopt_imu_noise(old.primary)  # the IMU's noise, measured, is kept
        self.outage = OutageMonitor(self._outage_config, rhythm=self._rhythm)
        """The GNSS outage monitor: usable fixes, the mode (NORMAL, BRIDGING ...)."""
        self.integrity.reset()
        self.bridge = PotentialBridge(cfg, self._potential_config)
        self.vertical_prior = VerticalPrior()
        """The last fixes' height as a prediction through a gap, beside the INS's."""
        self.publisher = Publisher(cfg.status_rate_hz, self.outage, self.integrity, self.bridge)
        self.coast: InertialCoast | None = None
        """The free-inertial references (with the blend, once the frame exists)."""
        self._rx_last_usable_t_s: dict[int, float] = {}
        self._rejected_beyond_bound: set[int] = set()
        """Receivers of which a fix, since the last one used, was rejected with its
        horizontal position beyond the prediction's bound (:meth:`_within_bound`)."""
        self.frame: LocalFrame | None = None
        self._next_outage_tick_s = -math.inf
        self._fix_fused = False
        """A fix was fused since the last publication (``publish_on_fix``)."""
        self.bridge_evidence.reset()
        self._bridge_cv = False
        """This gap is carried by constant velocity (the evidence said the inertial bridge
        is worse): the pass-through publishes until GNSS is back."""
        if self.imu_innovations is not None:
            self.imu_innovations.restart()

    # ------------------------------------------------------------------ entry point

    def handle(self, sample: Sample) -> list[Output]:
        """Take one sample; return what to publish (possibly nothing)."""
        if self._pending_state is not None:
            restored = self._restore_now(sample.t_s)
            return restored + self.handle(sample)
        kind = type(sample)
        self._sample_counts[kind] += 1
        if kind is RawSolution:
            # kept for the integrity monitor; its time is mapped from GPS time, not the
            # autopilot's own: it does not move the engine's clock
            self._raw = sample  # type: ignore[assignment]
            return []
        if kind is GnssSignalReport:  # neither does a raw receiver's report
            alerts: list[Output] = list(self.signal.on_report(sample))  # type: ignore[arg-type]
            self._account(alerts)
            return alerts
        t_s = sample.t_s
        watch = self.watch
        resumed: list[Output] = []
        if kind in _DATA_KINDS:
            # a data kind (IMU, attitude, fix): each carries its arrival time
            silence_s = watch.on_data(t_s, sample.t_rx_s)  # type: ignore[union-attr]
            if silence_s is not None:
                resumed = self._after_silence(t_s, silence_s)
        elif kind is RebootEvent and watch.silent:
            text = "reboot: restart from next fix"  # one STATUSTEXT
            resumed = [Alert(t_s, AlertCode.DATA_BACK, Severity.NOTICE, text)]
        handler = self._handlers.get(kind)
        outputs = handler(sample) if handler is not None else []
        if resumed:
            outputs = resumed + outputs
        watch = self.watch  # a new one after a reboot
        if not watch.started:
            watch.start(t_s)
        now = self.now_s
        if now is None or t_s > now:
            self.now_s = now = t_s
        if self.outage.last_fused_t_s is not None:
            # hot path (every IMU sample): the outage clock is ticked at most every
            # OUTAGE_TICK_S, publication when the integer period index advances
            # (publish.tick, inline)
            if now >= self._next_outage_tick_s:
                self._next_outage_tick_s = now + OUTAGE_TICK_S
                outputs += self._gap_started(self.outage.tick(now))
            if self.config.publish_on_fix:
                last_s = self._last_publish_s  # due times to within 1 us (0.1 is not binary)
                if (
                    now > last_s
                    and now >= last_s + self.config.min_publish_interval_s - DUE_EPS_S
                    and (self._fix_fused or now >= self._publish_due_s - DUE_EPS_S)
                ):
                    outputs += self._publish_on_fix(now)
            else:
                tick = math.floor(now * self._publish_rate_hz + 1e-6)
                if tick > self._publish_tick:
                    self._publish_tick = tick
                    outputs += self._publish(now)
        if watch.waiting:
            if self.outage.mode is not NavMode.INIT:
                outputs += watch.navigating(now)
            elif now >= watch.no_gnss_due_s:
                outputs += watch.tick(now)
        if not outputs:
            return outputs
        self._account(outputs)
        return outputs

    # ------------------------------------------------------------------ clock

    def next_due_s(self) -> float:
        """When :meth:`on_clock` next has something to raise, on the autopilot clock (s;
        ``inf``: nothing until the next sample): ``GNSS_LOST`` or ``LOST`` of the outage
        monitor, ``NO_DATA`` or ``NO_GNSS`` (:mod:`.silence`)."""
        due = self.watch.next_due_s()
        outage = self.outage
        last = outage.last_fused_t_s
        if last is not None:
            if outage.mode in (NavMode.NORMAL, NavMode.DEGRADED):
                due = min(due, last + outage.timeout_s + DUE_EPS_S)
            elif outage.mode in (NavMode.BRIDGING, NavMode.REACQUIRING):
                due = min(due, last + outage.config.max_bridge_s + DUE_EPS_S)
        return due

    def on_clock(self, t_s: float) -> list[Output]:
        """The autopilot clock reached ``t_s`` with no sample (a driver's timer during a
        silence, at :meth:`next_due_s`): the outage monitor's and the silence watch's
        alerts that are due. Publishes nothing: without data there is nothing to carry
        the solution with, and after ``silence_timeout_s`` the navigation restarts."""
        # the silence first: when it is due with the GNSS loss, NO_DATA says both
        outputs: list[Output] = list(self.watch.tick(t_s))
        if self.outage.last_fused_t_s is not None:
            outputs += self._gap_started(self.outage.tick(t_s))
        if outputs:
            self._account(outputs)
        return outputs

    def _gap_started(self, alerts: list[Alert]) -> list[Alert]:
        """At a GNSS loss, choose the bridge's motion model on the evidence (inertial
        prediction or constant velocity, :mod:`.bridge_choice`); the loss alert says which
        when it is constant velocity. A loss while every stream is silent or stalled is
        said by the silence's ``NO_DATA`` (:mod:`.silence`)."""
        if not alerts:
            return alerts
        out: list[Alert] = []
        for alert in alerts:
            if alert.code is AlertCode.GNSS_LOST:
                navs = self.navigators
                carrying_blend = navs.primary is not None and navs.navigator is navs.primary
                self._bridge_cv = carrying_blend and self.bridge_evidence.constant_velocity_better()
                if self._bridge_cv:
                    log.info(
                        "t=%.2f s: gap bridged by constant velocity (%s)",
                        alert.t_s,
                        self.bridge_evidence.describe(),
                    )
                    self.stats.gnss["gap_bridged_cv"] += 1
                    alert = dataclasses.replace(alert, text=alert.text + " on velocity")
                if self.watch.silent:
                    # NO_DATA, in force, already says GNSS is gone with every other stream
                    # (a slow link's GNSS timeout may outlast its silence timeout)
                    self.stats.gnss["loss_in_silence"] += 1
                    continue
                if self.watch.stalled(alert.t_s, self.outage.median_fix_interval_s):
                    # every stream stopped, GNSS with them: one alert, the silence's
                    self.stats.gnss["loss_in_silence"] += 1
                    alert = self.watch.announce(alert.t_s)
            out.append(alert)
        return out

    def _after_silence(self, t_s: float, silence_s: float) -> list[Output]:
        """The first data sample after ``silence_s`` of none: the navigation restarts from
        the next usable fix (nothing carried across the silence); ``DATA_BACK``."""
        log.warning("data back after %.1f s of silence: navigation restarts", silence_s)
        self.stats.silences += 1
        self._restart_navigation()
        self.watch.restarted(t_s)
        text = f"after {silence_s:.1f} s: restart from next fix"
        return [Alert(t_s, AlertCode.DATA_BACK, Severity.NOTICE, text)]

    def _account(self, outputs: list[Output]) -> None:
        """Count the alerts among ``outputs``; a heading change moves the navigators; an
        integrity report gets the signal monitor's jamming and spoofing verdicts."""
        for i, out in enumerate(outputs):
            if type(out) is IntegrityReport:
                outputs[i] = self.signal.stamp(out)
            elif isinstance(out, Alert):
                self.stats.alerts[out.code.value] += 1
                if out.code in _HEADING_CODES:
                    self.state_changes += 1
                if out.code is AlertCode.HDG_APPLIED:
                    self._heading_applied()
                elif out.code is AlertCode.HDG_UNDONE:
                    self._heading_undone()

    def self_change(self, t_s: float, kind: str, text: str, receiver_id: int | None = None) -> None:
        """The service changed itself at ``t_s`` (``kind``: lag, stamp, noise, grade, reset;
        ``text``: what, by how much; ``receiver_id``: whose fixes it concerns): what that
        invalidates is re-seeded and never blamed on a receiver (:mod:`.self_change`)."""
        reseed(self, t_s, kind, text, receiver_id)

    # ------------------------------------------------------------------ handlers

    def _on_imu(self, sample: ImuSample) -> list[Output]:
        if self.navigators.on_imu(sample):
            self.integrity.spoof.on_imu(sample)
            if self.coast is not None:
                self.coast.on_imu(sample)
        check = self.imu_check
        if check is None:
            return []
        source = (sample.source, sample.imu_id)
        if self._imu_source is None:
            self._imu_source = source
        if source != self._imu_source:
            return []
        verdict = check.on_imu(sample)
        if verdict is None or not verdict.doubted:
            return []
        why = f"IMU noise gyro {verdict.gyro_ratio:.1f}x accel {verdict.acc_ratio:.1f}x its grade's"
        return self._widen_grade(verdict.t_s, why)

    def _imu_check(self) -> ImuNoiseCheck | None:
        """The noise check of the configured blend grade, when a wider grade (the MEMS
        autopilot IMU's) exists to fall back to."""
        cfg, mems = self._blend_config, IMU_GRADES["mems"]
        if not self.config.imu_grade_check or (
            cfg.gyro_arw_rad_rts >= mems.gyro_noise_density_radps_rthz
            and cfg.accel_vrw_mps_rts >= mems.acc_noise_density_mps2_rthz
        ):
            return None
        return ImuNoiseCheck(cfg.gyro_arw_rad_rts, cfg.accel_vrw_mps_rts)

    def _grade_narrower_than_mems(self) -> bool:
        """Is any figure of the configured blend grade narrower than a MEMS autopilot
        IMU's (white noise or bias): is there a wider grade to fall back to?"""
        cfg, mems = self._blend_config, BlendConfig.for_grade("mems")
        return (
            cfg.accel_vrw_mps_rts < mems.accel_vrw_mps_rts
            or cfg.gyro_arw_rad_rts < mems.gyro_arw_rad_rts
            or cfg.accel_bias_sigma_mps2 < mems.accel_bias_sigma_mps2
            or cfg.gyro_bias_sigma_radps < mems.gyro_bias_sigma_radps
        )

    def _check_innovation(self, fix: GnssFix, update: GnssUpdate) -> list[Output]:
        """One fix's NIS for the in-flight grade check (the blend carrying, normal
        navigation); the grade widened when its windows say so (:meth:`_widen_grade`)."""
        check = self.imu_innovations
        if check is None or update.reason not in ("", "gate") or update.dof <= 0:
            return []
        window = check.on_innovation(
            fix.t_s, update.nis, update.dof, update.gate, self.outage.self_consistent(fix)
        )
        if window is None or not check.doubted:
            return []
        failed = [w for w in check.windows if w.failed]
        worst = max(w.ratio for w in failed)
        why = (
            f"IMU innovations up to {worst:.1f}x their grade's in {len(failed)} of "
            f"{len(check.windows)} windows"
        )
        return self._widen_grade(fix.t_s, why)

    def _widen_grade(self, t_s: float, why: str) -> list[Output]:
        """The IMU is worse than its configured grade (``why``: the noise at rest or in
        flight, or the innovations in flight): the MEMS grade from now on for the blend
        (attitude-aided) and no inertial references, the navigation restarted from the
        next fix (a receiver excluded on the narrow grade's word is pardoned)."""
        mems = BlendConfig.for_grade("mems")
        cfg = self._blend_config
        self._blend_config = dataclasses.replace(
            cfg,
            mode=mems.mode,
            accel_vrw_mps_rts=max(cfg.accel_vrw_mps_rts, mems.accel_vrw_mps_rts),
            gyro_arw_rad_rts=max(cfg.gyro_arw_rad_rts, mems.gyro_arw_rad_rts),
            accel_bias_sigma_mps2=max(cfg.accel_bias_sigma_mps2, mems.accel_bias_sigma_mps2),
            gyro_bias_sigma_radps=max(cfg.gyro_bias_sigma_radps, mems.gyro_bias_sigma_radps),
        )
        self._coast_config = CoastConfig.for_grade("mems")
        self.integrity.spoof.widen_grade("mems")
        self._grade_widened = True
        self.imu_check = None
        self.imu_innovations = None
        self.integrity.stats["imu_grade_widened"] += 1
        self._restart_navigation()
        self.self_change(t_s, "grade", why)
        text = f"{why}: widened to mems, restart; receiver not blamed"
        log.warning("t=%.2f s IMU grade doubted: %s", t_s, text)
        return [Alert(t_s, AlertCode.IMU_GRADE, Severity.WARNING, text)]

    def _on_attitude(self, sample: AttitudeSample) -> list[Output]:
        gap_attitude = self.config.gap_attitude
        in_gap = self.outage.mode in OUTAGE_MODES
        if gap_attitude != "autopilot":
            # through a gap, an autopilot fusing our output corrects its attitude with it
            # (and after the fix is withdrawn, that attitude still carries it)
            self.navigators.hold_attitude(
                in_gap and (gap_attitude == "rates" or self.autopilot_fuses_output)
            )
        # the autopilot's GNSS is ours: through our gap its heading is unaided too, and
        # its tilt when nothing else levels it
        self.navigators.attitude_unaided(in_gap, tilt=in_gap and self.tilt_aiding.lost)
        self._yaw_rad = sample.yaw_rad
        self._attitude = sample
        self.heading.on_attitude(sample)  # the heading buffer, and the pitch: on ground?
        correction_rad = self.heading.correction_rad
        if self.navigators.on_attitude(sample, correction_rad):
            self.integrity.spoof.on_attitude(sample, correction_rad)
            if self.coast is not None:
                self.coast.on_attitude(sample, correction_rad)
        return []

    def _on_autopilot_solution(self, sample: AutopilotSolution) -> list[Output]:
        aiding = self.tilt_aiding
        was = aiding.held
        if aiding.on_solution(sample.t_s, sample.lat_rad, sample.lon_rad) and not was:
            log.info("t=%.2f s the autopilot holds its position still", sample.t_s)
        return []

    def _on_heartbeat(self, sample: HeartbeatSample) -> list[Output]:
        self.tilt_aiding.on_heartbeat(sample.vehicle_type)
        return []

    def _on_baro(self, sample: BaroSample) -> list[Output]:
        # one barometer: the first source heard (an autopilot may send the same sensor
        # twice, SCALED_PRESSURE and HIGHRES_IMU, at different times of validity)
        source = (sample.source, sample.baro_id)
        if self._baro_source is None:
            self._baro_source = source
        elif source != self._baro_source:
            self.integrity.stats["baro_other_source"] += 1
            return []
        if self.baro.on_sample(sample) and self.outage.mode in OUTAGE_MODES:
            self._baro_to_blend(sample.t_s)
        return []

    def _baro_to_blend(self, t_s: float) -> None:
        """Through a GNSS gap, the calibrated barometer's height into the blend."""
        blend, frame = self.navigators.primary, self.frame
        if (
            not self._engine_baro_in_blend
            or frame is None
            or not isinstance(blend, BlendNavigator)
            or self.navigators.navigator is not blend
            or not blend.initialised
        ):
            return
        ref = self.baro.reference(t_s, 0.0)
        state = blend.predict(blend.imu_t_s) if ref is not None else None
        if ref is None or state is None:
            return
        lat, lon, _ = frame.ned_to_lla(state.pos_ned_m)
        pos_d_m = float(frame.lla_to_ned(lat, lon, ref.alt_msl_m)[2])
        blend.on_height(t_s, pos_d_m, ref.white_var_m2, ref.offset_var_m2)

    def _baro_at(self, fix: GnssFix) -> BaroReference | None:
        """The calibrated barometric height at the fix's time (None: none, or on the ground)."""
        if self._on_ground():
            return None
        return self.baro.reference(fix.t_s, self._integrity_config.pair_max_dt_s)

    def _calibrate_baro(self, fix: GnssFix, meas: GnssMeasurement) -> None:
        """The barometer follows trusted GNSS only: fused, in normal navigation, no fault."""
        if (
            self.outage.mode is NavMode.NORMAL
            and not self.integrity.fault_detected
            and int(fix.fix_type) >= int(FixType.FIX_3D)
        ):
            self.baro.calibrate(fix.t_s, fix.alt_msl_m, float(meas.pos_var_ned_m2[2]))

    def _on_landed(self, sample: LandedStateSample) -> list[Output]:
        state = sample.landed_state
        self._landed = state
        on_ground = None if state is LandedState.UNDEFINED else state is LandedState.ON_GROUND
        # one input of the ground decision: "in air" alone is not a flight (ArduPlane
        # says so as soon as it rolls); the next fix decides with the motion
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
        self._heading_changed(sigma_rad)

    def _heading_undone(self) -> None:
        """The navigators restart their heading error from the uncorrected heading, with
        the 1-sigma the blend gives it before any correction: as if none had been applied."""
        self._heading_changed(self._blend_config.heading_prior_sigma_rad)

    def _heading_changed(self, sigma_rad: float) -> None:
        """The correction was applied or undone: the navigators and the inertial references
        take the latest attitude again with the correction now in force (a strapdown blend
        restarts its heading from it), then every navigator restarts its heading error at
        ``sigma_rad`` (1-sigma)."""
        attitude = self._attitude
        correction_rad = self.heading.correction_rad
        if attitude is not None and self.navigators.on_attitude(attitude, correction_rad):
            self.integrity.spoof.on_attitude(attitude, correction_rad)
            if self.coast is not None:
                self.coast.on_attitude(attitude, correction_rad)
        self.navigators.reset_heading(sigma_rad)

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
        # the heading is corrected during the taxi (Markelov et al.); in the air the
        # correction (applied or not) stands until back on the ground
        heading = self.heading
        was_airborne = heading.airborne
        heading.observe_fix(fix)
        outputs: list[Output]
        if heading.airborne:
            outputs = [] if was_airborne else heading.end_taxi(fix.t_s)
        else:
            outputs = heading.on_gnss(fix)
        navs = self.navigators
        navs.select(self.now_s)
        rid = fix.receiver_id
        # another receiver's separation (or a reference) showed it wrong: no reset to it
        verdict = self.outage.assess(
            fix,
            shown_wrong=self.integrity.shown_wrong(rid),
            now_s=self.now_s,
            within_bound=self._within_bound,
        )
        outputs += verdict.alerts
        self.watch.gnss_timeout_s = self.outage.timeout_s if self._rhythm.slow else 0.0
        if not verdict.usable:
            self.stats.gnss[verdict.reason] += 1
            return outputs
        if self.frame is None:
            self._anchor(LocalFrame(fix.lat_rad, fix.lon_rad, fix.alt_msl_m))
        if self.frame is None:  # _anchor sets it; keeps mypy honest
            raise ValueError("no local frame after anchoring")
        meas = gnss_measurement(fix, self.frame)
        outputs += self._spoof_check(fix, meas)
        # the references are for flight: on the ground, before the taxi correction, the
        # autopilot's heading can be degrees off and taxi turns turn that into metres
        refs: Mapping[str, NavState] | None = (
            self.coast.references(meas.t_s)
            if self.coast is not None and not self._on_ground()
            else None
        )
        raw = self._raw_reference(meas.t_s)
        if raw is not None:
            refs = {**(refs or {}), "tdprp": raw}
            self.integrity.stats["raw_reference_tested"] += 1
        if not self._fuse_receiver(fix):
            # the other receiver: the integrity monitor's independent solution only
            self.stats.gnss[f"rx{rid}_monitored"] += 1
            outputs += self.integrity.on_fix(
                fix, meas, None, references=refs, baro=self._baro_at(fix)
            )
            return outputs
        if verdict.reinitialise:
            # rejected by the innovation alone for long enough, or after an outage beyond
            # the gate: the navigator, not the self-consistent receiver, is what is off
            return outputs + self._reset_to(fix, meas)
        if self.integrity.exclude(rid):
            self.stats.gnss["excluded"] += 1
            if self.integrity.shown_wrong(rid):
                self.outage.rejection_explained(rid)  # independent evidence: no reset clock
            else:
                self.outage.rejected(fix)
            outputs += self.integrity.on_fix(
                fix, meas, None, references=refs, baro=self._baro_at(fix)
            )
            return outputs
        if self._bridge_cv and self.outage.mode in OUTAGE_MODES:
            # the gap was carried by constant velocity: a fix that agrees with it ends the
            # gap, and the blend, whose inertial prediction was judged worse, restarts there
            navs.sync_fallback()
            if navs.fallback.on_gnss(meas, gate=True).fused:
                self._bridge_cv = False
                return outputs + self._reset_to(fix, meas)
        predicted = self.bridge.reference(meas.t_s)
        blend = navs.primary if navs.navigator is navs.primary else None
        probing = isinstance(blend, BlendNavigator) and self.outage.mode in (
            NavMode.NORMAL,
            NavMode.DEGRADED,
        )
        if probing:
            self.bridge_evidence.before_fusion(meas, blend)  # type: ignore[arg-type]
        update = navs.on_gnss(meas, verdict.gate)
        moved = self._noise_watch.moved(navs.primary) if update.fused else ""
        if moved:  # the blend's measured IMU noise (counted and logged)
            self.self_change(fix.t_s, "noise", moved)
        if probing and update.fused:
            self.bridge_evidence.after_fusion(meas, blend)  # type: ignore[arg-type]
        if probing and verdict.gate:
            widened = self._check_innovation(fix, update)
            if widened:  # the navigation restarts from the next fix
                return outputs + widened
        vouched = False
        if not update.fused and update.reason == "gate":
            self.stats.gnss["gate_rejected"] += 1
            self.outage.rejected(fix)
            if not _position_within_bound(update):
                self._rejected_beyond_bound.add(rid)
            # the receiver's own evidence vouches for the fix: the gate measured the
            # prediction's error; fused anyway (repeated, the outage monitor resets)
            if self.outage.vouched(fix) and not self.integrity.shown_wrong(rid):
                update = navs.force(meas, update)
                vouched = update.fused
                if not vouched:  # its height failed: beyond what its own evidence covers
                    self.outage.rejection_unvouched(rid)
        if update.fused:
            self._fix_fused = True
            self.stats.gnss["fused_vouched" if vouched else "fused"] += 1
            if not vouched:
                self.outage.used(fix)
                self._rejected_beyond_bound.discard(rid)
            self.publisher.last_fused_fix = fix
            self.publisher.satellites = fix.satellites or 0
            self.bridge.add_fix(meas)
            self._vertical_prior_add(meas)
        elif update.reason != "gate":
            self.stats.gnss[update.reason] += 1
        # after a gap the navigator's prediction, not the receiver, is what is uncertain: a
        # failed innovation then is the outage logic's (gate, reacquire, re-initialise), and
        # must not exclude the receiver (which would stop the re-initialisation forever);
        # nor must the innovation of a fix the receiver's own evidence vouches for
        bridged = (verdict.gate and self.outage.mode in OUTAGE_MODES) or vouched
        outputs += self.integrity.on_fix(
            fix,
            meas,
            None if bridged else update,
            predicted=predicted,
            references=refs,
            baro=self._baro_at(fix),
        )
        if update.fused:
            self._calibrate_baro(fix, meas)
        if update.fused or update.reason == "gate":
            outputs += self.outage.gate_result(fix.t_s, update.fused)
        return outputs

    @property
    def gnss_lag_sigma_s(self) -> float | None:
        """What is not known of receiver 0's fix placement against the IMU, s (None: not
        measured): set by the pipeline from the lag it measures, for the spoofing
        monitor's test (a misplaced fix moves by its acceleration times the error)."""
        return self.integrity.spoof.lag_sigma_s

    @gnss_lag_sigma_s.setter
    def gnss_lag_sigma_s(self, sigma_s: float | None) -> None:
        self.integrity.spoof.lag_sigma_s = sigma_s

    def _spoof_check(self, fix: GnssFix, meas: GnssMeasurement) -> list[Output]:
        """The fix against the IMU (:mod:`companion.integrity.spoof`); at a detection the
        navigators restart from the reference that saw it, carried to now by the IMU."""
        navigator = self.navigators.navigator
        nav = navigator.predict(self.now_s) if navigator.initialised and self.now_s else None
        rid = fix.receiver_id
        step = self.integrity.spoof.on_fix(
            fix,
            meas,
            nav,
            airborne=not self._on_ground(),
            suspected=self.integrity.fde.shown_wrong(rid),
            own_verdict=self.signal.receiver_verdict(rid, fix.t_s),
            evidence=self.signal.spoof_evidence(rid, fix.t_s),
        )
        state = step.rollback
        if state is not None:
            var_p = np.diag(state.pos_cov_ned_m2).copy()
            var_v = np.diag(state.vel_cov_ned_m2ps2).copy()
            meas_ref = GnssMeasurement(
                state.t_s, state.pos_ned_m, var_p, state.vel_ned_mps, var_v,
                FixType.FIX_3D, fix.receiver_id,
            )  # fmt: skip
            self.navigators.rebase(state, meas_ref)
            self.bridge.restart()
            self.vertical_prior.restart()
            self.stats.gnss["spoof_rollback"] += 1
        return list(step.alerts)

    def _within_bound(self, fix: GnssFix) -> bool:
        """Has the solution held the receiver of ``fix`` within its bound: every fix of it
        rejected since its last one used had its horizontal position innovation inside
        :data:`RESET_ALERT_CHI2` (the gate may have failed on the velocity), and ``fix``
        itself (carried to the navigator's time by its own velocity) is inside it from the
        navigator's position, their covariances combined? A reset to it then moves the
        solution by no more than it said it could be off (outage monitor: not a fault)."""
        if fix.receiver_id in self._rejected_beyond_bound:
            return False
        frame, now = self.frame, self.now_s
        if frame is None or now is None:
            return False
        state = self.navigators.navigator.predict(now)
        if state is None:
            return False
        meas = gnss_measurement(fix, frame)
        vel = meas.vel_ned_mps[:2]
        carried = meas.pos_ned_m[:2] + (vel if np.all(np.isfinite(vel)) else 0.0) * (now - fix.t_s)
        d = state.pos_ned_m[:2] - carried
        cov = state.pos_cov_ned_m2[:2, :2] + np.diag(meas.pos_var_ned_m2[:2])
        if not np.all(np.isfinite(d)) or not np.all(np.isfinite(cov)):
            return False
        try:
            d2 = float(d @ np.linalg.solve(cov, d))
        except np.linalg.LinAlgError:
            return False
        return d2 <= RESET_ALERT_CHI2

    def _raw_reference(self, t_s: float) -> AnchoredState | None:
        """The raw receiver's carrier-phase solution as a reference for the separation tests
        (``ref:tdprp``), in the local frame: only one that FIS-RAIM tested and passed, and
        within ``pair_max_dt_s`` of ``t_s``."""
        raw, frame = self._raw, self.frame
        if raw is None or frame is None or not raw.trusted:
            return None
        if abs(t_s - raw.t_s) > self._integrity_config.pair_max_dt_s:
            return None
        return AnchoredState(
            t_s=raw.t_s,
            pos_ned_m=frame.lla_to_ned(raw.lat_rad, raw.lon_rad, raw.alt_msl_m),
            vel_ned_mps=raw.vel_ned_mps,
            pos_cov_ned_m2=raw.pos_cov_ned_m2,
            vel_cov_ned_m2ps2=raw.vel_cov_ned_m2ps2,
            anchor_t_s=raw.anchor_t_s,
        )

    def _reset_to(self, fix: GnssFix, meas: GnssMeasurement) -> list[Output]:
        """Re-initialise every navigator from ``fix`` (its exclusion, if any, lifted)."""
        self.integrity.fde.pardon(fix.receiver_id)
        self.navigators.reinitialise(meas)
        self.bridge.restart()
        self.bridge.add_fix(meas)
        self.vertical_prior.restart()
        self._vertical_prior_add(meas)
        self.outage.used(fix)
        self._rejected_beyond_bound.discard(fix.receiver_id)
        self.stats.gnss["reinitialised"] += 1
        self.publisher.last_fused_fix = fix
        self._fix_fused = True
        self.self_change(fix.t_s, "reset", f"navigator re-initialised to rx{fix.receiver_id}")
        return list(self.outage.reinitialised(fix.t_s))

    def _fuse_receiver(self, fix: GnssFix) -> bool:
        """Fuse the primary receiver; the other only while the primary is unusable."""
        self._rx_last_usable_t_s[fix.receiver_id] = fix.t_s
        primary = self.config.primary_receiver
        if fix.receiver_id == primary:
            return True
        last_primary = self._rx_last_usable_t_s.get(primary, -math.inf)
        primary_down = fix.t_s - last_primary > self.outage.timeout_s or self.integrity.exclude(
            primary
        )
        return primary_down

    # ------------------------------------------------------------------ configuration

    def reconfigure(self, block: str, config: object) -> None:
        """Run with ``config`` as the ``[block]`` configuration from now on.

        Only the keys of :data:`LIVE_KEYS` may differ from the running configuration
        (ValueError otherwise, and nothing changes): each estimator holding the block
        reads it from the new configuration at its next use, and a restart of the
        navigation (an autopilot reboot) keeps it.
        """
        current: object = {
            "engine": self.config,
            "outage": self._outage_config,
            "heading": self._heading_config,
            "integrity": self._integrity_config,
        }.get(block)
        if current is None or type(config) is not type(current):
            raise ValueError(f"[{block}] cannot be changed while running")
        changed = {
            f.name
            for f in dataclasses.fields(current)  # type: ignore[arg-type]
            if getattr(current, f.name) != getattr(config, f.name)
        }
        fixed = changed - LIVE_KEYS[block]
        if fixed:
            raise ValueError(f"[{block}] {', '.join(sorted(fixed))}: only at a restart")
        if isinstance(config, EngineConfig):
            self.config = config
            if "publish_rate_hz" in changed:
                self._publish_rate_hz = config.publish_rate_hz
                now = self.now_s
                self._publish_tick = -1 if now is None else tick(now, config.publish_rate_hz)
                self._publish_due_s = min(
                    self._publish_due_s, self._last_publish_s + 1.0 / config.publish_rate_hz
                )
            if "status_rate_hz" in changed:
                self.publisher.set_status_rate(config.status_rate_hz, self.now_s)
        elif isinstance(config, OutageConfig):
            self._outage_config = self.outage.config = config
        elif isinstance(config, HeadingConfig):
            self._heading_config = self.heading.config = config
        elif isinstance(config, IntegrityConfig):
            self._integrity_config = self.integrity.config = config
            self.integrity.protection.config = config  # where the live keys are read

    # ------------------------------------------------------------------ persistence

    def persistent_state(self) -> dict[str, object]:
        """What must survive a restart of the service during a flight (JSON-safe):
        the heading correction, tied to the autopilot clock it was made on."""
        return {"t_s": self.now_s, "heading": self.heading.to_state()}

    def restore(self, state: dict[str, object]) -> None:
        """Restore :meth:`persistent_state` once the first sample shows the same
        autopilot boot (its clock not behind the saved time); otherwise drop it."""
        self._pending_state = state

    def _restore_now(self, t_s: float) -> list[Output]:
        """Restore the pending state at the first sample (time ``t_s``); a restored
        correction (anything but IDLE) is announced: ``HDG_RESTORED <status> <value>``."""
        state, self._pending_state = self._pending_state, None
        if state is None:
            return []
        saved_t = state.get("t_s")
        if not isinstance(saved_t, int | float) or t_s < saved_t:
            log.info("saved state is from an earlier autopilot boot: not restored")
            return []
        heading = state.get("heading")
        if not isinstance(heading, dict):
            log.warning("saved state has no heading block: not restored")
            return []
        try:
            self.heading = HeadingCorrector.from_state(self._heading_config, heading)
        except ValueError as exc:
            log.warning("saved heading state rejected: %s", exc)
            return []
        text = self.heading.describe()
        log.info("heading correction restored: %s", text)
        if self.heading.status is HeadingStatus.IDLE:
            return []
        self.stats.alerts[AlertCode.HDG_RESTORED.value] += 1
        return [Alert(t_s, AlertCode.HDG_RESTORED, Severity.NOTICE, text)]

    # ------------------------------------------------------------------ publication

    def _state_now(self, t_s: float) -> NavState | None:
        navs = self.navigators
        navigator = navs.navigator
        if not navigator.initialised:
            return None
        t_s = max(t_s, self.now_s or t_s)
        mode = self.outage.mode
        if self._bridge_cv and mode in OUTAGE_MODES:
            navs.sync_fallback()
            fallback_state = navs.fallback.predict(t_s)
            if fallback_state is not None:
                if self.config.vertical_prior and mode in GAP_MODES:
                    return self._vertical_prior_carry(fallback_state)
                return fallback_state
        state = navigator.predict(t_s)
        if state is None:
            return None
        no_imu = navigator is navs.fallback
        state = self.bridge.carry(state, t_s, mode, no_imu)
        if self.config.vertical_prior and not no_imu and mode in GAP_MODES:
            state = self._vertical_prior_carry(state)
        if mode in OUTAGE_MODES and self.integrity.spoof.episodes:
            state = self.integrity.spoof.bridge(state)  # the last state no spoofed fix touched
        return state

    def _vertical_prior_add(self, meas: GnssMeasurement) -> None:
        if self.config.vertical_prior:
            self.vertical_prior.add_fix(
                meas.t_s, float(meas.pos_ned_m[2]), float(meas.pos_var_ned_m2[2])
            )

    def _vertical_prior_carry(self, state: NavState) -> NavState:
        """The height combined with the recent fixes' (:mod:`companion.nav.vertical_prior`)."""
        cov = state.pos_cov_ned_m2
        both = self.vertical_prior.combine(state.t_s, float(state.pos_ned_m[2]), float(cov[2, 2]))
        if both is None:
            return state
        pos_d_m, var_m2 = both
        pos = state.pos_ned_m.copy()
        pos[2] = pos_d_m
        # the horizontal is the INS's; its correlation with the height is scaled with it
        k = math.sqrt(var_m2 / cov[2, 2])
        new_cov = cov.copy()
        new_cov[2, :2] *= k
        new_cov[:2, 2] *= k
        new_cov[2, 2] = var_m2
        return dataclasses.replace(state, pos_ned_m=pos, pos_cov_ned_m2=new_cov)

    def _publish_on_fix(self, now_s: float) -> list[Output]:
        """A publication at ``now_s`` (``publish_on_fix``) and when the next one is due if
        no fix is fused meanwhile: a period of ``publish_rate_hz`` later, unless that
        falls within half a period of the next fix expected (the last fused one and the
        median fix interval): then half a fix interval after the expected fix, so that a
        fix a little late is still published on arrival, not held back by the minimum
        interval behind a publication just before it. Never more than :data:`MAX_HOLD_S`."""
        period_s = 1.0 / self._publish_rate_hz
        interval_s = self.outage.median_fix_interval_s  # 0 until known: the longest wait
        if self._fix_fused:
            self._next_fix_s = now_s + interval_s
            self._fix_fused = False
        # the next tick of the publish_rate_hz grid: a due time of now + period would
        # slip by each sample's wait past it (a 10 Hz output fell to 8.5 Hz in a gap)
        due_s = (math.floor(now_s * self._publish_rate_hz + 1e-6) + 1) * period_s
        expected_s = self._next_fix_s
        if expected_s >= now_s and due_s > expected_s - 0.5 * period_s:
            late_s = LATE_FIX_INTERVALS * interval_s if interval_s > 0.0 else MAX_HOLD_S
            due_s = expected_s + late_s
        self._publish_due_s = min(due_s, now_s + MAX_HOLD_S)
        return self._publish(now_s)

    def _publish(self, now_s: float) -> list[Output]:
        self._last_publish_s = now_s
        t_s = publication_time_s(now_s)
        self.navigators.select(self.now_s)
        state = self._state_now(t_s)
        if state is None or self.frame is None:
            return []
        self._anchor_coast()
        if self._maybe_reanchor(state):
            state = self._state_now(t_s)
            if state is None:  # shifting a state never uninitialises it; keeps mypy honest
                return []
        outputs = self.publisher.publish(
            t_s, state, self.frame, self.heading, self._yaw_rad, self._landed
        )
        if self.autopilot_fuses_output:
            outputs[0] = self._feed_or_withdraw(outputs[0])
        self.stats.solutions += 1
        return outputs

    def _feed_or_withdraw(self, out: Output) -> Output:
        """Through a gap, the solution for an autopilot that fuses it: "no fix" once its
        horizontal accuracy has passed ``gap_feed_max_h_acc_m`` (a multirotor's:
        ``gap_feed_no_airspeed_max_h_acc_m``), until GNSS is trusted."""
        if not isinstance(out, NavSolution):
            return out
        if self.outage.mode not in OUTAGE_MODES:
            self._feed_withdrawn = False
            return out
        limit_m = (
            self.config.gap_feed_no_airspeed_max_h_acc_m
            if self.tilt_aiding.no_airspeed
            else self.config.gap_feed_max_h_acc_m
        )
        if not self._feed_withdrawn and out.h_acc_m > limit_m:
            self._feed_withdrawn = True
            self.stats.gnss["gap_feed_withdrawn"] += 1
            log.info(
                "t=%.2f s: the autopilot's fix withdrawn (%.1f m 1-sigma)", out.t_s, out.h_acc_m
            )
        if self._feed_withdrawn and out.fix_type is not FixType.NO_FIX:
            return dataclasses.replace(out, fix_type=FixType.NO_FIX)
        return out

    # ------------------------------------------------------------------ frame and references

    def _anchor(self, frame: LocalFrame) -> None:
        self.frame = frame
        self.navigators.shift_frame(frame, frame)
        if (
            self.navigators.primary is not None
            and self.config.inertial_reference
            and not self._grade_widened
        ):
            gravity = gravity_ned_mps2(frame.lat0_rad, frame.alt0_m)
            self.coast = InertialCoast(self._coast_config, gravity)

    def _on_ground(self) -> bool:
        """On the ground by the heading's ground decision, when the autopilot sends a
        landed state (False when it sends none)."""
        return not self.heading.airborne and self._landed not in (None, LandedState.UNDEFINED)

    def _anchor_coast(self) -> None:
        """Re-anchor a due coasting slot from the blend at its newest IMU time, only while
        the blend fuses trusted GNSS (never from a solution a fault may have pulled)."""
        coast, blend = self.coast, self.navigators.primary
        if (
            coast is None
            or not isinstance(blend, BlendNavigator)
            or self.navigators.navigator is not blend
        ):
            return
        if (
            self._on_ground()
            or self.outage.mode is not NavMode.NORMAL
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

    def _maybe_reanchor(self, state: NavState) -> bool:
        """Re-anchor the frame at the solution when it is far from the anchor; True if it
        did (states computed before are then in the old frame)."""
        if self.frame is None or self.frame.distance_from_anchor_m(state.pos_ned_m) < (
            self.config.reanchor_distance_m
        ):
            return False
        lat, lon, alt = self.frame.ned_to_lla(state.pos_ned_m)
        new = LocalFrame(lat, lon, alt)
        navs = self.navigators
        navs.sync_fallback()  # the fixes it has not taken are in the old frame
        navs.shift_frame(self.frame, new)
        self.integrity.shift_frame(self.frame, new)
        if self.coast is not None:
            offset = new.lla_to_ned(self.frame.lat0_rad, self.frame.lon0_rad, self.frame.alt0_m)
            self.coast.shift_frame(rotation_between_frames(self.frame, new), offset)
        self.bridge.restart()  # its window of fixes is in the old frame
        self.vertical_prior.restart()
        self.frame = new
        self.stats.reanchors += 1
        log.info("local frame re-anchored at %.6f, %.6f", math.degrees(lat), math.degrees(lon))
        return True
