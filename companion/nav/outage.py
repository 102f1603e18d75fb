"""Outage management: is a GNSS fix usable, and which mode is the navigation in?

Detects loss (message timeout, no fix), downgrade (RTK fixed -> float -> DGPS/3D
-> none, an accuracy jump, old RTK corrections: RTK_LOST, then RTK_BACK when RTK
returns) and stale fixes (the receiver repeating or freezing its last corrected
co-ordinates while the aircraft moves: the failure Grzegorzewski (2005) reports
from flight trials, with errors up to 2 km at jet speed). It runs the mode machine

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
from dataclasses import dataclass, field

from companion.nav.earth import radii_of_curvature_m
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
    """No usable fix for this long -> GNSS_LOST and BRIDGING. Five missed epochs at 5 Hz."""
    min_fix_type: int = ranged(int(FixType.FIX_3D), ge=0, le=int(FixType.PPP))
    """Fixes below this type are not usable (2-D fixes carry no height)."""
    max_bridge_s: float = ranged(120.0, gt=0.0, finite=False)
    """Bridging longer than this -> LOST (the published fix type drops to none)."""
    reacquire_fixes: int = ranged(3, ge=1)
    """Consecutive fixes that must pass the gate after an outage before GNSS_BACK."""
    reacquire_max_rejects: int = ranged(25, ge=1)
    """After this many consecutive gate rejections while reacquiring, the navigator is
    re-initialised from GNSS (its prediction, not the fixes, is then what is wrong)."""
    stale_min_speed_mps: float = 1.0
    """Repeated co-ordinates are legitimate when parked: staleness is judged above this speed."""
    stale_repeats: int = ranged(2, ge=1)
    """Bit-identical consecutive positions (while moving) that make a fix stale."""
    stale_motion_ratio: float = ranged(0.2, gt=0.0, lt=1.0)
    """A fix that moved less than this fraction of the navigator's predicted motion ..."""
    stale_window_s: float = ranged(1.0, gt=0.0, finite=False)
    """... over at least this long is frozen (stale) even if not bit-identical."""
    accuracy_jump_ratio: float = ranged(4.0, gt=1.0, finite=False)
    """h_acc growing by this factor over its recent best marks the fix DEGRADED."""
    rtk_max_age_s: float = ranged(10.0, gt=0.0, finite=False)
    """RTK / DGPS corrections older than this (GPS2_RAW dgps_age) are treated as lost."""
    downgrade_memory_s: float = ranged(600.0, gt=0.0, finite=False)
    """The best fix type seen within this window is what 'not degraded' means."""

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

    # ------------------------------------------------------------------ per fix

    def assess(self, fix: GnssFix, nav_speed_mps: float | None) -> FixAssessment:
        """Judge one fix; ``nav_speed_mps`` is the navigator's ground speed (None if unknown)."""
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
        stale_reason = self._stale_check(rx, fix, pos, nav_speed_mps)
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
        if not reinit and not alerts:
            return _USABLE  # the common verdict, shared (it is immutable)
        if reinit:
            alerts.append(
                Alert(
                    t,
                    AlertCode.FAULT,
                    Severity.WARNING,
                    f"prediction rejected {self._gated_rejects} fixes: reinit from GNSS",
                )
            )
        return FixAssessment(True, "ok", not reinit, reinit, tuple(alerts))

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
        if self.mode is NavMode.REACQUIRING and self._gated_ok >= self.config.reacquire_fixes:
            start = self.outage_start_t_s if self.outage_start_t_s is not None else t_s
            alerts.append(
                Alert(t_s, AlertCode.GNSS_BACK, Severity.NOTICE, f"after {t_s - start:.1f} s")
            )
            self.outage_start_t_s = None
            self._set_mode(self._good_mode())
        return alerts

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
        if silent_s > cfg.gnss_timeout_s and self.mode in (NavMode.NORMAL, NavMode.DEGRADED):
            stale = any(r.stale for r in self._receivers.values())
            reason = "stale fixes" if stale else self._silence_reason(t_s)
            self.outage_start_t_s = self.last_fused_t_s
            alerts.append(
                Alert(t_s, AlertCode.GNSS_LOST, Severity.WARNING, f"{reason} {silent_s:.1f} s")
            )
            alerts.append(Alert(t_s, AlertCode.BRIDGING, Severity.WARNING, "position carried"))
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
        self._gated_ok = 0
        self._gated_rejects = 0
        self._degraded = False

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
        if t_s - newest > self.config.gnss_timeout_s:
            return "no GNSS messages"
        return "no usable fix"

    def _stale_check(
        self,
        rx: _ReceiverState,
        fix: GnssFix,
        pos: tuple[float, float, float],
        nav_speed_mps: float | None,
    ) -> str:
        cfg = self.config
        moving = nav_speed_mps is not None and nav_speed_mps > cfg.stale_min_speed_mps
        if rx.last_pos is not None and pos == rx.last_pos and moving:
            rx.repeats += 1
        else:
            rx.repeats = 0
        if rx.repeats > 0 and rx.repeats + 1 >= cfg.stale_repeats:
            return f"repeated position x{rx.repeats + 1}"
        # frozen: far less motion than the navigator predicts over a window
        if not moving or nav_speed_mps is None:
            rx.anchor_t_s, rx.anchor_pos, rx.moved_expected_m = fix.t_s, pos, 0.0
            return ""
        if rx.anchor_t_s is None or rx.anchor_pos is None or rx.last_t_s is None:
            rx.anchor_t_s, rx.anchor_pos, rx.moved_expected_m = fix.t_s, pos, 0.0
            return ""
        rx.moved_expected_m += nav_speed_mps * max(0.0, fix.t_s - rx.last_t_s)
        if fix.t_s - rx.anchor_t_s < cfg.stale_window_s:
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
