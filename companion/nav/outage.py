"""Outage management: is a GNSS fix usable, and which mode is the navigation in?

Detects loss (message timeout, no fix), downgrade (RTK fixed -> float -> DGPS/3D
-> none, an accuracy jump, old RTK corrections: RTK_LOST, then RTK_BACK when RTK
returns) and stale fixes (the receiver repeating or freezing its last corrected
co-ordinates while its own velocity says it moves: the failure Grzegorzewski (2005)
reports from flight trials, with errors up to 2 km at jet speed). A receiver is
judged by its own evidence (:mod:`companion.nav.receiver_checks`), never by the
navigator's prediction it is meant to correct: a drifting prediction must not
make a healthy receiver look frozen.

Rejection is bounded: a receiver whose fixes the navigator has not taken (gate
rejections, exclusion by the integrity monitor) for ``reset_after_rejection_s``
while it is self-consistent, and that no other receiver contradicts, has the
navigator reset to it (``reinitialise``), with an alert. When the receiver's
consistent chain reaches back to the last fix the navigator took (it moved from
an accepted fix exactly as its own velocity says), rejection convicts the
prediction, not the receiver: the reset comes after ``reset_after_rejected_fixes``
rejected fixes (a single outlier of the gate does not restart the navigator).
Resets are alerted at most once per ``reset_alert_interval_s`` (the next alert
counts those in between). Compare ArduPilot EKF3
(``AP_NavEKF3_PosVelFusion.cpp``: the innovation gate, then after a timeout the
position reset to GNSS) and PX4 EKF2 (GNSS quality checks, then a reset when
fusion has timed out). It runs the mode machine

    INIT -> NORMAL <-> DEGRADED
              |  ^          |
              v  |          v
           BRIDGING -> REACQUIRING -> NORMAL / DEGRADED
              |
              v
             LOST (bridged longer than the navigator can be trusted)

and says which alerts to raise. It never fuses anything itself: the engine asks
:meth:`OutageMonitor.assess` before offering a fix to the navigator and reports
the navigator's gate verdict back with :meth:`OutageMonitor.gate_result`.

Pure: no I/O, no clock; time comes from the samples.

The alerts are :class:`~companion.types.AlertCode` values; the modes are
described in ``docs/architecture.md``.

References
----------
Grzegorzewski (2005), "Navigating by a position potential in 3-D": stale
DGPS/RTK co-ordinates. El-Mowafy (2005), RTK networks for precision approach
with an adaptive GPS/INS blend: correction outages and GNSS de-weighting.
"""

from __future__ import annotations

import logging
import math
import statistics
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from companion.nav.earth import radii_of_curvature_m
from companion.nav.fix_rate import FixRhythm
from companion.nav.gnss import h_sigma_m
from companion.nav.receiver_checks import (
    ReceiverCheckConfig,
    ReceiverConsistency,
    horizontal_offset_m,
)
from companion.ranges import check_ranges, ranged
from companion.types import Alert, AlertCode, FixType, GnssFix, NavMode, Severity

log = logging.getLogger(__name__)

RTK_TYPES = (FixType.RTK_FLOAT, FixType.RTK_FIXED)
OUTAGE_MODES = frozenset({NavMode.BRIDGING, NavMode.LOST, NavMode.REACQUIRING})
"""Modes after GNSS was lost and before it is trusted again: the navigator has been
carried without GNSS."""


@dataclass(frozen=True, slots=True)
class OutageConfig:
    """Thresholds of the outage logic (all times on the autopilot clock)."""

    gnss_timeout_s: float = ranged(1.0, gt=0.0, finite=False)
    """No usable fix for this long -> GNSS_LOST (mode BRIDGING). Five missed epochs at 5 Hz."""
    timeout_fix_intervals: float = ranged(1.5, ge=1.0)
    """A receiver slower than ``gnss_timeout_s`` allows (a telemetry link's 1 Hz) is late
    only after this many of its own fix intervals (the median of the last
    :data:`FIX_INTERVALS_KEPT` between its consecutive fixes, late ones included: kept
    between fused fixes only, the intervals that made it late would never count) plus
    its fixes' usual delivery delay (the median age of a fix when it arrives, against the
    newest sample time): a fix that is merely not due yet is no outage. A slow receiver
    (``slow_enter_s``) is late only after this many times the longest lateness of its
    recent fixes (:mod:`companion.nav.fix_rate`), at most ``gnss_timeout_max_s``."""
    slow_enter_s: float = ranged(0.5, gt=0.0, finite=False)
    """A receiver whose fixes arrive with a median lateness (the silence before each
    arrival, over its last 60) above this is slow and irregular (a telemetry link):
    ``GNSS_SLOW``, once, and its own timeout. Half of ``gnss_timeout_s``: a 5 Hz receiver
    that misses epochs is not slow."""
    slow_leave_s: float = ranged(0.35, gt=0.0, finite=False)
    """... and regular again (``GNSS_STEADY``) only once that median is below this."""
    slow_max_interval_s: float = ranged(3.0, gt=0.0, finite=False)
    """A silence this long or longer before a fix is an outage, not the link's rhythm:
    it does not lengthen the timeout."""
    gnss_timeout_max_s: float = ranged(4.0, gt=0.0, finite=False)
    """The longest GNSS timeout a slow receiver's rhythm can make (s)."""
    min_fix_type: int = ranged(int(FixType.FIX_3D), ge=0, le=int(FixType.PPP))
    """Fixes below this type are not usable (2-D fixes carry no height)."""
    max_bridge_s: float = ranged(120.0, gt=0.0, finite=False)
    """Bridging longer than this -> LOST (the published fix type drops to none)."""
    reacquire_fixes: int = ranged(3, ge=1)
    """Consecutive fixes that must pass the gate after an outage before GNSS_BACK (one for a
    receiver slower than ``gnss_timeout_s`` allows: three of its fixes would take longer
    than most of its gaps, every one of them unused)."""
    reacquire_max_rejects: int = ranged(25, ge=1)
    """After this many consecutive gate rejections while reacquiring, the navigator is
    re-initialised from GNSS (its prediction, not the fixes, is then what is wrong)."""
    stale_min_speed_mps: float = 1.0
    """Repeated co-ordinates are legitimate when parked: staleness is judged above this speed
    (the receiver's own ground speed)."""
    stale_repeats: int = ranged(2, ge=1)
    """Bit-identical consecutive positions (while moving) that make a fix stale."""
    stale_motion_ratio: float = ranged(0.2, gt=0.0, lt=1.0)
    """A fix that moved less than this fraction of the distance its own reported speed
    covers ..."""
    stale_window_s: float = ranged(1.0, gt=0.0, finite=False)
    """... over at least this long is frozen (stale) even if not bit-identical."""
    accuracy_jump_ratio: float = ranged(4.0, gt=1.0, finite=False)
    """h_acc growing by this factor over its recent best marks the fix DEGRADED."""
    rtk_max_age_s: float = ranged(10.0, gt=0.0, finite=False)
    """RTK / DGPS corrections older than this (GPS2_RAW dgps_age) are treated as lost."""
    downgrade_memory_s: float = ranged(600.0, gt=0.0, finite=False)
    """The best fix type seen within this window is what 'not degraded' means."""
    reset_after_rejection_s: float = ranged(3.0, gt=0.0, finite=False)
    """A receiver the navigator has rejected (gate, exclusion) for this long while it is
    self-consistent (:mod:`companion.nav.receiver_checks`) and no other receiver
    contradicts it: the navigator is reset to its fix (an innovation alone never keeps
    a receiver out longer). A few fix intervals beyond the gate's own false alarms;
    shorter than EKF3's 7-10 s GPS retry time, because the blend on a MEMS IMU drifts
    metres in seconds."""
    min_satellites: int = ranged(6, ge=0)
    """A receiver reporting fewer satellites is not self-consistent (PX4 EKF2: 6)."""
    max_hdop: float = ranged(4.0, gt=0.0, finite=False)
    """A receiver reporting a larger HDOP is not self-consistent (looser than PX4's
    pre-flight PDOP 2.5: this re-admits a receiver in flight, it does not arm)."""
    reset_after_rejected_fixes: int = ranged(2, ge=1)
    """... or after this many rejected fixes when the receiver's consistent chain reaches
    back to the last fix the navigator took (it moved from an accepted fix as its own
    velocity says: the prediction is what is off)."""
    reset_alert_interval_s: float = ranged(60.0, ge=0.0, finite=False)
    """At most one alert per this interval for the resets to a receiver (the next one
    says how many there were since)."""
    contradiction_sigmas: float = ranged(5.0, gt=0.0)
    """Another self-consistent receiver further than this many combined 1-sigmas from a
    fix contradicts it: no reset to it (the integrity monitor arbitrates)."""

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True, slots=True)
class FixAssessment:
    """Verdict on one fix before fusion."""

    usable: bool
    reason: str
    gate: bool
    """Whether the navigator must gate it (always true once the navigator runs;
    false only for the very first fix and a forced re-initialisation)."""
    reinitialise: bool
    alerts: tuple[Alert, ...]


_USABLE = FixAssessment(True, "ok", True, False, ())
"""The verdict on a usable fix that raises nothing (most fixes)."""


@dataclass(slots=True)
class _ReceiverState:
    last_t_s: float | None = None
    last_pos: tuple[float, float, float] | None = None
    repeats: int = 0
    anchor_t_s: float | None = None
    anchor_pos: tuple[float, float, float] | None = None
    moved_expected_m: float = 0.0
    best_type: int = 0
    best_type_t_s: float = -math.inf
    best_hacc_m: float = math.inf
    best_hacc_t_s: float = -math.inf
    was_rtk: bool = False
    rtk_lost_t_s: float | None = None
    """When this receiver's RTK_LOST was raised; None when RTK was not lost (RTK_BACK
    is raised only for a receiver that announced RTK_LOST)."""
    stale: bool = False
    checks: ReceiverConsistency = field(default_factory=ReceiverConsistency)
    """Its own consistency (quality, increments against its velocity)."""
    last_fix: GnssFix | None = None
    rejected_since_t_s: float | None = None
    """When the navigator began rejecting it (None: its last fix was used)."""
    last_used_t_s: float | None = None
    """Time of its last fix the engine used."""
    rejected_fixes: int = 0
    """Its fixes rejected since the last used one."""
    unvouched: bool = False
    """One of those was rejected for what its own evidence does not cover (its height):
    no early reset, only the bounded time's."""


FIX_INTERVALS_KEPT = 20
"""Intervals between fixes (and delivery delays) whose medians set a slow receiver's timeout."""


@dataclass(slots=True)
class OutageMonitor:
    """The mode machine of GNSS availability (see the module docstring)."""

    config: OutageConfig = field(default_factory=OutageConfig)
    mode: NavMode = NavMode.INIT
    last_fused_t_s: float | None = None
    outage_start_t_s: float | None = None
    _receivers: dict[int, _ReceiverState] = field(default_factory=dict)
    _gated_ok: int = 0
    _gated_rejects: int = 0
    _lost_reason: str = ""
    _degraded: bool = False
    _checks: ReceiverCheckConfig = field(default_factory=ReceiverCheckConfig)
    resets: int = 0
    """Resets of the navigator to a rejected receiver (bounded rejection)."""
    resets_within_bound: int = 0
    """... of which the solution held the receiver's fix within its published bound: the
    prediction's noise, not a fault (not alerted)."""
    _median_fix_interval_s: float = 0.0
    _fix_intervals_s: deque[float] = field(default_factory=lambda: deque(maxlen=FIX_INTERVALS_KEPT))
    _fix_ages_s: deque[float] = field(default_factory=lambda: deque(maxlen=FIX_INTERVALS_KEPT))
    _median_fix_age_s: float = 0.0
    _reset_alerted_t_s: float = -math.inf
    _resets_unalerted: int = 0
    rhythm: FixRhythm = field(default_factory=FixRhythm)
    """The link's rhythm of fixes: slow or not (kept by the engine across restarts)."""
    resets_self_change: int = 0
    """... of which came within the horizon of a change the service made to itself (not
    alerted: :meth:`service_changed`)."""
    _self_change_until_s: float = -math.inf

    # ------------------------------------------------------------------ per fix

    def assess(
        self,
        fix: GnssFix,
        *,
        shown_wrong: bool = False,
        now_s: float | None = None,
        within_bound: Callable[[GnssFix], bool] | None = None,
    ) -> FixAssessment:
        """Judge one fix by the receiver's own evidence (see the module docstring);
        ``shown_wrong``: an independent source (another receiver, an inertial reference)
        shows this receiver wrong, so a rejection of it is never ended by a reset;
        ``now_s``: the newest sample time before it (its delivery delay is kept);
        ``within_bound``: does the solution already hold this fix within its published
        bound (then a reset to it moves nothing a pilot was told: counted and logged,
        not alerted; None: every reset is alerted)."""
        cfg = self.config
        rx = self._receivers.get(fix.receiver_id)
        if rx is None:
            rx = self._receivers[fix.receiver_id] = _ReceiverState()
        alerts: list[Alert] = []
        t = fix.t_s
        ftype = int(fix.fix_type)
        if ftype < cfg.min_fix_type:
            rx.last_t_s = t
            alerts += self._downgrade_alerts(rx, fix, ftype)
            return FixAssessment(False, f"fix_type_{ftype}", True, False, tuple(alerts))

        pos = (fix.lat_rad, fix.lon_rad, fix.alt_msl_m)
        if rx.last_t_s is not None and t <= rx.last_t_s and pos == rx.last_pos:
            # the same fix again (same time, same co-ordinates): nothing new, no alert
            return FixAssessment(False, "repeated", True, False, tuple(alerts))
        rx.checks.on_fix(fix, self._check_config())
        rx.last_fix = fix
        alerts += self._rhythm(rx, t, now_s)
        self._fix_interval(rx, t)
        if now_s is not None and math.isfinite(now_s):
            self._fix_ages_s.append(max(0.0, now_s - t))
            self._median_fix_age_s = statistics.median(self._fix_ages_s)
        stale_reason = self._stale_check(rx, fix, pos)
        rx.last_t_s = t
        rx.last_pos = pos
        if stale_reason:
            if not rx.stale:
                rx.stale = True
                alerts.append(
                    Alert(
                        t,
                        AlertCode.GNSS_STALE,
                        Severity.WARNING,
                        f"rx{fix.receiver_id} {stale_reason}",
                    )
                )
                log.warning("receiver %d stale at t=%.2f s: %s", fix.receiver_id, t, stale_reason)
            return FixAssessment(False, "stale", True, False, tuple(alerts))
        rx.stale = False

        alerts += self._downgrade_alerts(rx, fix, ftype)
        if self.mode is NavMode.INIT:
            return FixAssessment(True, "first_fix", False, False, tuple(alerts))
        # fixes rejected since the outage, whether or not one has been fused since: when
        # GNSS returns and the prediction has drifted beyond the gate, no fix ever passes
        reinit = self._gated_rejects >= cfg.reacquire_max_rejects and self.mode in OUTAGE_MODES
        why = f"prediction rejected {self._gated_rejects} fixes: reinit from GNSS"
        if not reinit and not shown_wrong:
            why = self._reset_reason(rx, fix)
            reinit = bool(why)
        if not reinit and not alerts:
            return _USABLE  # the common verdict, shared (it is immutable)
        if reinit and self.mode in OUTAGE_MODES and self.outage_start_t_s is not None:
            # the reset ends an outage: its GNSS_BACK says "re-initialised" (one alert for
            # one change, not a FAULT and a GNSS_BACK at the same instant)
            self.resets += 1
            log.warning("t=%.2f s: %s (ends the outage)", t, why)
        elif reinit:
            if t < self._self_change_until_s:
                self.resets += 1
                self.resets_self_change += 1
                log.info("t=%.2f s: %s (after a change of the service's own: not alerted)", t, why)
            elif within_bound is not None and within_bound(fix):
                self.resets += 1
                self.resets_within_bound += 1
                log.info("t=%.2f s: %s (within the solution's bound: not alerted)", t, why)
            else:
                alerts += self._reset_alert(t, why)
        return FixAssessment(True, "ok", not reinit, reinit, tuple(alerts))

    def vouched(self, fix: GnssFix) -> bool:
        """Does the receiver's own evidence vouch for ``fix``: self-consistent, with a
        chain reaching back to its last used fix, and no other receiver contradicting?
        (Then a failed innovation measures the navigator's error, not the receiver's.)"""
        rx = self._receivers.get(fix.receiver_id)
        if rx is None or rx.last_fix is not fix or rx.last_used_t_s is None:
            return False
        start = rx.checks.chain_start_t_s
        return (
            start is not None
            and start <= rx.last_used_t_s
            and rx.checks.consistent(fix.t_s, self._check_config())
            and not self._contradicted(fix)
        )

    def self_consistent(self, fix: GnssFix) -> bool:
        """Is the receiver of ``fix`` self-consistent at its time (its position increments
        agree with its own velocity) and uncontradicted by another receiver? Then a large
        innovation of the fix is the navigator's prediction error, not the receiver's."""
        rx = self._receivers.get(fix.receiver_id)
        return (
            rx is not None
            and rx.last_fix is fix
            and rx.checks.consistent(fix.t_s, self._check_config())
            and not self._contradicted(fix)
        )

    def rejected(self, fix: GnssFix) -> None:
        """The engine did not use a usable fix of this receiver (excluded, or the gate
        failed): the rejection clock runs from the first such fix."""
        rx = self._receivers.get(fix.receiver_id)
        if rx is None:
            return
        rx.rejected_fixes += 1
        if rx.rejected_since_t_s is None:
            rx.rejected_since_t_s = fix.t_s

    def rejection_unvouched(self, receiver_id: int) -> None:
        """The last rejection was for what the receiver's own evidence does not cover (its
        height): no reset before ``reset_after_rejection_s``."""
        rx = self._receivers.get(receiver_id)
        if rx is not None:
            rx.unvouched = True

    def rejection_explained(self, receiver_id: int) -> None:
        """The receiver is held out on independent evidence (another receiver, a
        reference): its rejection clock stops; no reset is due to it."""
        rx = self._receivers.get(receiver_id)
        if rx is not None:
            rx.rejected_since_t_s = None
            rx.rejected_fixes = 0
            rx.unvouched = False

    def used(self, fix: GnssFix) -> None:
        """The engine used this fix: the receiver's rejection clock stops."""
        rx = self._receivers.get(fix.receiver_id)
        if rx is not None:
            rx.rejected_since_t_s = None
            rx.rejected_fixes = 0
            rx.unvouched = False
            rx.last_used_t_s = fix.t_s

    def service_changed(self, t_s: float, receiver_id: int | None, horizon_s: float) -> None:
        """The service changed itself at ``t_s`` (the lag it places a receiver's fixes
        with, a reset of the navigator, its IMU grade): the rejection clock of that
        receiver (None: of every one) starts again (its rejections measured the service as
        it was), and a reset to a receiver within ``horizon_s`` is the service's own doing,
        not a fault: counted (``resets_self_change``) and logged, not alerted."""
        for rid, rx in self._receivers.items():
            if receiver_id is None or rid == receiver_id:
                rx.rejected_since_t_s = None
                rx.rejected_fixes = 0
                rx.unvouched = False
        self._self_change_until_s = max(self._self_change_until_s, t_s + horizon_s)

    def rejected_for_s(self, receiver_id: int, t_s: float) -> float:
        """How long the navigator has been rejecting this receiver at ``t_s`` (0: not)."""
        rx = self._receivers.get(receiver_id)
        if rx is None or rx.rejected_since_t_s is None:
            return 0.0
        return max(0.0, t_s - rx.rejected_since_t_s)

    def gate_result(self, t_s: float, fused: bool) -> list[Alert]:
        """The navigator's verdict on a usable fix; returns mode-change alerts."""
        alerts: list[Alert] = []
        if not fused:
            if self.mode in OUTAGE_MODES:
                self._gated_rejects += 1
                self._gated_ok = 0
            return alerts
        self.last_fused_t_s = t_s
        if self.mode is NavMode.INIT:
            self._set_mode(self._good_mode())
        elif self.mode in (NavMode.BRIDGING, NavMode.LOST):
            self._set_mode(NavMode.REACQUIRING)
            self._gated_ok = 1
            self._gated_rejects = 0
        elif self.mode is NavMode.REACQUIRING:
            self._gated_ok += 1
            self._gated_rejects = 0
        else:
            self._set_mode(self._good_mode())
        if self.mode is NavMode.REACQUIRING and self._gated_ok >= self._reacquire_fixes():
            start = self.outage_start_t_s if self.outage_start_t_s is not None else t_s
            alerts.append(
                Alert(t_s, AlertCode.GNSS_BACK, Severity.NOTICE, f"after {t_s - start:.1f} s")
            )
            self.outage_start_t_s = None
            self._set_mode(self._good_mode())
        return alerts

    def _rhythm(self, rx: _ReceiverState, t_s: float, now_s: float | None) -> list[Alert]:
        """The fix's lateness into the link's rhythm; ``GNSS_SLOW`` / ``GNSS_STEADY`` when
        the slow state changes (once per change)."""
        last = rx.last_t_s
        if last is None or t_s <= last:
            return []
        cfg = self.config
        arrival = t_s if now_s is None or not math.isfinite(now_s) else max(now_s, t_s)
        rhythm = self.rhythm
        changed = rhythm.on_fix(
            arrival - last, cfg.slow_enter_s, cfg.slow_leave_s, cfg.slow_max_interval_s
        )
        if changed is None:
            return []
        timeout = self.timeout_s
        if changed:
            # one STATUSTEXT (50 characters with "CMP GNSS_SLOW "); the longest in the log
            text = f"fix every {rhythm.median_s:.1f} s: loss after {timeout:.1f} s"
            log.warning("t=%.2f s GNSS slow: %s (longest %.1f s)", t_s, text, rhythm.longest_s)
            return [Alert(t_s, AlertCode.GNSS_SLOW, Severity.WARNING, text)]
        text = f"fix every {rhythm.median_s:.1f} s: loss after {timeout:.1f} s"
        return [Alert(t_s, AlertCode.GNSS_STEADY, Severity.NOTICE, text)]

    def _fix_interval(self, rx: _ReceiverState, t_s: float) -> None:
        """Keep the interval since the receiver's previous fix and the timeout it implies."""
        last = rx.last_t_s
        if last is None or t_s <= last:
            return
        self._fix_intervals_s.append(t_s - last)
        self._median_fix_interval_s = statistics.median(self._fix_intervals_s)

    def _reacquire_fixes(self) -> int:
        """Gated fixes that end an outage: ``reacquire_fixes``, one for a slow receiver."""
        cfg = self.config
        return 1 if self.timeout_s > cfg.gnss_timeout_s else cfg.reacquire_fixes

    @property
    def median_fix_interval_s(self) -> float:
        """Median interval between the last fused fixes (s; 0 until two were fused)."""
        return self._median_fix_interval_s

    @property
    def timeout_s(self) -> float:
        """The GNSS timeout in force: ``gnss_timeout_s``, or longer for a receiver slower
        than it allows (``timeout_fix_intervals`` of its median fix interval plus its
        fixes' median delivery delay) and, in the slow state, ``timeout_fix_intervals``
        of its longest recent lateness, at most ``gnss_timeout_max_s``."""
        cfg = self.config
        if self.rhythm.slow:
            longest = cfg.timeout_fix_intervals * self.rhythm.longest_s
            return max(cfg.gnss_timeout_s, min(cfg.gnss_timeout_max_s, longest))
        slow = cfg.timeout_fix_intervals * self._median_fix_interval_s + self._median_fix_age_s
        return max(cfg.gnss_timeout_s, slow)

    def reinitialised(self, t_s: float) -> list[Alert]:
        """The engine re-initialised the navigator from a fix; GNSS_BACK if it ends an outage."""
        alerts: list[Alert] = []
        if self.mode in OUTAGE_MODES and self.outage_start_t_s is not None:
            text = f"after {t_s - self.outage_start_t_s:.1f} s (re-initialised)"
            alerts.append(Alert(t_s, AlertCode.GNSS_BACK, Severity.NOTICE, text))
        self.last_fused_t_s = t_s
        self._gated_ok = 0
        self._gated_rejects = 0
        self.outage_start_t_s = None
        self._set_mode(self._good_mode())
        return alerts

    # ------------------------------------------------------------------ clock

    def tick(self, t_s: float) -> list[Alert]:
        """Advance the clock (called on every sample): timeouts and LOST."""
        alerts: list[Alert] = []
        cfg = self.config
        if self.last_fused_t_s is None:
            return alerts
        silent_s = t_s - self.last_fused_t_s
        # the time tests first: they are cheaper and almost always false
        if silent_s > self.timeout_s and self.mode in (NavMode.NORMAL, NavMode.DEGRADED):
            stale = any(r.stale for r in self._receivers.values())
            reason = "stale fixes" if stale else self._silence_reason(t_s)
            self.outage_start_t_s = self.last_fused_t_s
            # one alert per gap: the loss says the position is carried (no separate
            # BRIDGING text: a pilot hears one message per change)
            text = f"{reason} {silent_s:.1f} s: bridging"
            alerts.append(Alert(t_s, AlertCode.GNSS_LOST, Severity.WARNING, text))
            self._gated_rejects = 0
            self._set_mode(NavMode.BRIDGING)
        if silent_s > cfg.max_bridge_s and self.mode in (NavMode.BRIDGING, NavMode.REACQUIRING):
            alerts.append(
                Alert(
                    t_s, AlertCode.INTEGRITY, Severity.CRITICAL, f"bridged {silent_s:.0f} s: lost"
                )
            )
            self._set_mode(NavMode.LOST)
        return alerts

    def outage_s(self, t_s: float) -> float:
        """Seconds since the last fused fix while not NORMAL/DEGRADED, else 0."""
        if self.mode in (NavMode.NORMAL, NavMode.DEGRADED, NavMode.INIT):
            return 0.0
        if self.last_fused_t_s is None:
            return 0.0
        start = self.outage_start_t_s if self.outage_start_t_s is not None else self.last_fused_t_s
        return max(0.0, t_s - start)

    def reset(self) -> None:
        """Forget everything (autopilot reboot)."""
        self.mode = NavMode.INIT
        self.last_fused_t_s = None
        self.outage_start_t_s = None
        self._receivers.clear()
        self._fix_intervals_s.clear()
        self._median_fix_interval_s = 0.0
        self._fix_ages_s.clear()
        self._median_fix_age_s = 0.0
        self.rhythm.clear()
        self._gated_ok = 0
        self._gated_rejects = 0
        self._degraded = False
        self._self_change_until_s = -math.inf

    def receiver_usable(self, receiver_id: int) -> bool:
        """False while a receiver is stale."""
        rx = self._receivers.get(receiver_id)
        return rx is None or not rx.stale

    # ------------------------------------------------------------------ internals

    def _good_mode(self) -> NavMode:
        return NavMode.DEGRADED if self._degraded else NavMode.NORMAL

    def _set_mode(self, mode: NavMode) -> None:
        if mode is not self.mode:
            log.info("mode %s -> %s", self.mode.value, mode.value)
            self.mode = mode

    def _silence_reason(self, t_s: float) -> str:
        if not self._receivers:
            return "no fix"
        newest = max((r.last_t_s or -math.inf) for r in self._receivers.values())
        if t_s - newest > self.timeout_s:
            return "no GNSS messages"
        return "no usable fix"

    def _check_config(self) -> ReceiverCheckConfig:
        cfg = self.config
        checks = self._checks
        if checks.min_satellites != cfg.min_satellites or checks.max_hdop != cfg.max_hdop:
            checks = self._checks = ReceiverCheckConfig(
                min_satellites=cfg.min_satellites, max_hdop=cfg.max_hdop
            )
        return checks

    def _reset_alert(self, t_s: float, why: str) -> list[Alert]:
        """Count a reset; its alert unless one was raised within the alert interval."""
        self.resets += 1
        log.warning("t=%.2f s: %s", t_s, why)
        if t_s - self._reset_alerted_t_s < self.config.reset_alert_interval_s:
            self._resets_unalerted += 1
            return []
        if self._resets_unalerted:
            why += f" ({self._resets_unalerted} more since the last alert)"
        self._reset_alerted_t_s = t_s
        self._resets_unalerted = 0
        return [Alert(t_s, AlertCode.FAULT, Severity.WARNING, why)]

    def _reset_reason(self, rx: _ReceiverState, fix: GnssFix) -> str:
        """Why the navigator must be reset to this fix now, or '' (module docstring)."""
        since = rx.rejected_since_t_s
        t = fix.t_s
        cfg = self.config
        if since is None or not rx.checks.consistent(t, self._check_config()):
            return ""
        start = rx.checks.chain_start_t_s
        linked = start is not None and rx.last_used_t_s is not None and start <= rx.last_used_t_s
        if linked and rx.rejected_fixes >= cfg.reset_after_rejected_fixes and not rx.unvouched:
            why = f"rx{fix.receiver_id} moved as its velocity says since its last used fix"
        elif t - since >= cfg.reset_after_rejection_s:
            why = f"rx{fix.receiver_id} rejected {t - since:.1f} s but self-consistent"
        else:
            return ""
        if self._contradicted(fix):
            return ""
        return why + ": navigator reset to it"

    def _contradicted(self, fix: GnssFix) -> bool:
        """Does another self-consistent receiver, at about the same time, put the aircraft
        more than ``contradiction_sigmas`` combined 1-sigmas from this fix?"""
        cfg = self.config
        for rid, other in self._receivers.items():
            ofix = other.last_fix
            if rid == fix.receiver_id or ofix is None or other.stale:
                continue
            dt = fix.t_s - ofix.t_s
            if abs(dt) > 0.5 or not other.checks.consistent(ofix.t_s, self._check_config()):
                continue
            dn, de = horizontal_offset_m(ofix, fix)
            if ofix.vel_ne_mps is not None:
                dn -= float(ofix.vel_ne_mps[0]) * dt
                de -= float(ofix.vel_ne_mps[1]) * dt
            sigma = math.hypot(h_sigma_m(fix), h_sigma_m(ofix))
            if math.hypot(dn, de) > cfg.contradiction_sigmas * sigma:
                return True
        return False

    def _stale_check(
        self,
        rx: _ReceiverState,
        fix: GnssFix,
        pos: tuple[float, float, float],
    ) -> str:
        cfg = self.config
        # the receiver's own speed: a drifting prediction must not make it look frozen
        speed_mps = fix.ground_speed_mps
        moving = speed_mps > cfg.stale_min_speed_mps
        if rx.last_pos is not None and pos == rx.last_pos and moving:
            rx.repeats += 1
        else:
            rx.repeats = 0
        if rx.repeats > 0 and rx.repeats + 1 >= cfg.stale_repeats:
            return f"repeated position x{rx.repeats + 1}"
        # frozen: far less motion than the receiver's own speed says, over a window
        if not moving:
            rx.anchor_t_s, rx.anchor_pos, rx.moved_expected_m = fix.t_s, pos, 0.0
            return ""
        if (
            rx.anchor_t_s is None
            or rx.anchor_pos is None
            or rx.last_t_s is None
            or fix.t_s - rx.last_t_s > self._check_config().max_increment_dt_s
        ):
            # (after a gap in the fixes the speed says nothing about the distance)
            rx.anchor_t_s, rx.anchor_pos, rx.moved_expected_m = fix.t_s, pos, 0.0
            return ""
        rx.moved_expected_m += speed_mps * max(0.0, fix.t_s - rx.last_t_s)
        # the window closes once the motion expected is beyond the receiver's own noise
        # (a slow receiver's velocity noise must not make it look frozen)
        if (
            fix.t_s - rx.anchor_t_s < cfg.stale_window_s
            or rx.moved_expected_m < self._check_config().chain_tol_m
        ):
            return ""
        moved_m = _horizontal_distance_m(rx.anchor_pos, pos)
        expected_m = rx.moved_expected_m
        rx.anchor_t_s, rx.anchor_pos, rx.moved_expected_m = fix.t_s, pos, 0.0
        if moved_m < cfg.stale_motion_ratio * expected_m:
            return f"frozen: moved {moved_m:.1f} m, expected {expected_m:.1f} m"
        return ""

    def _downgrade_alerts(self, rx: _ReceiverState, fix: GnssFix, ftype: int) -> list[Alert]:
        cfg = self.config
        t = fix.t_s
        alerts: list[Alert] = []
        if ftype >= rx.best_type or t - rx.best_type_t_s > cfg.downgrade_memory_s:
            rx.best_type, rx.best_type_t_s = ftype, t
        corrections_old = (
            fix.dgps_age_s is not None
            and fix.dgps_age_s > cfg.rtk_max_age_s
            and ftype >= int(FixType.DGPS)
        )
        is_rtk = ftype in RTK_TYPES and not corrections_old
        if rx.was_rtk and not is_rtk:
            why = "corrections old" if corrections_old else FixType(ftype).name
            alerts.append(
                Alert(t, AlertCode.RTK_LOST, Severity.WARNING, f"rx{fix.receiver_id} -> {why}")
            )
            rx.rtk_lost_t_s = t
        elif is_rtk and rx.rtk_lost_t_s is not None:
            text = f"rx{fix.receiver_id} -> {FixType(ftype).name} after {t - rx.rtk_lost_t_s:.1f} s"
            alerts.append(Alert(t, AlertCode.RTK_BACK, Severity.NOTICE, text))
            rx.rtk_lost_t_s = None
        rx.was_rtk = is_rtk
        if fix.h_acc_m is not None:
            if fix.h_acc_m <= rx.best_hacc_m or t - rx.best_hacc_t_s > cfg.downgrade_memory_s:
                rx.best_hacc_m, rx.best_hacc_t_s = fix.h_acc_m, t
        jump = fix.h_acc_m is not None and fix.h_acc_m > cfg.accuracy_jump_ratio * rx.best_hacc_m
        self._degraded = ftype < rx.best_type or jump or corrections_old
        return alerts


def _horizontal_distance_m(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """Small-distance horizontal separation of two (lat_rad, lon_rad, alt) points, m."""
    m_m, n_m = radii_of_curvature_m(a[0])
    dn = (b[0] - a[0]) * (m_m + a[2])
    de = (b[1] - a[1]) * (n_m + a[2]) * math.cos(a[0])
    return math.hypot(dn, de)
