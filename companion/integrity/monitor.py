"""The integrity monitor: fault detection and exclusion, solution separation, protection levels.

Two entry points, both pure (no I/O, no clock; time is the samples' ``t_s``):

* :meth:`IntegrityMonitor.on_fix` for every GNSS fix the navigator was offered:
  fix-level FDE (the navigator's innovation chi-square against a threshold from
  ``false_alarm_prob``; the potential filter's prediction ellipsoid, S0, when
  given) and solution separation (S3) of this receiver against the other
  receivers and any independent reference solutions. A failed fix is counted
  and alerted (``CMP FAULT ...``); a receiver found faulty is *excluded* for
  ``recovery_s`` after its last failure (:meth:`exclude` tells the engine not to
  offer its fixes). A fault that cannot be attributed to one receiver (two
  receivers disagree and nothing else arbitrates), or a failed fix the
  navigator fused anyway, leaves the fault *unresolved*: integrity is lost.
* :meth:`IntegrityMonitor.on_solution` for every published solution: flight
  phase, protection levels (HPL/VPL from the covariance), the alert limit of
  the phase and required approach category, ``integrity_ok``, the available
  approach category; ``CMP INTEGRITY`` / ``CMP CAT`` alerts on changes;
  ``CMP_HPL``, ``CMP_VPL``, ``CMP_CAT`` and an :class:`IntegrityReport` at
  ``report_rate_hz``.

Which solutions are separated: receiver pairs (a later fix of one receiver
against the latest fix of the other, extrapolated with its velocity), and
each receiver against each *reference* the caller passes to :meth:`on_fix`:
solutions that by construction do not contain this receiver's recent fixes
(an INS prediction coasting from a reset older than the window, a second
navigator that excludes the receiver). A navigator that fuses the receiver
follows a slow ramp (its innovation stays small), which is why its own
prediction is used only in the fix-level tests.

An inertial reference (:class:`companion.integrity.coast.CoastState`) drifts:
its separation series restarts when it re-anchors (a step at re-anchoring is
not a fault), and its window tests account for its velocity and acceleration
error (:class:`companion.integrity.separation.ReferenceDrift`). A separation
that fails against a reference blames the receiver. Two receivers that
disagree are told apart by their separations from third solutions (other
receivers, references): the one that fails a test against a third solution
while the other passes them all is the culprit; otherwise the fault stays
unresolved until the evidence comes. While receivers disagree, a reference
anchored less than one separation window before the disagreement was detected
may carry the fault (it was anchored from the navigator fusing the faulty
receiver) and does not count; and a reference that fails against a receiver the
navigator does not fuse, while another receiver is in use, proves nothing about
it (the reference carries the fused receiver's errors): the fault is unresolved.

References
----------
SEEDS.md S3 (solution separation, slope and residual tests), S0 (ellipsoid
test of a new fix against the potential prediction; alert limits), S1
(requirement tables). RTCA DO-229 appendix J (protection levels).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2
from scipy.stats import f as f_dist

from companion.integrity.coast import CoastState
from companion.integrity.limits import (
    AlertLimit,
    ApproachCategory,
    FlightPhase,
    alert_limit,
    available_category,
)
from companion.integrity.phase import PhaseClassifier, PhaseConfig
from companion.integrity.protection import (
    ProtectionLevels,
    k_horizontal,
    k_vertical,
    protection_levels,
)
from companion.integrity.separation import ReferenceDrift, SeparationResult, SeparationTracker
from companion.nav.frames import LocalFrame
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState, rotation_between_frames
from companion.types import (
    Alert,
    AlertCode,
    FloatArray,
    GnssFix,
    IntegrityReport,
    LandedState,
    NamedValue,
    NavMode,
    NavSolution,
    Output,
    Severity,
)

log = logging.getLogger(__name__)

PairKey = tuple[str, str]
_REF = "ref:"
"""Prefix of a reference solution's name in a pair key (receivers are ``rx<id>``)."""
_FLOAT_MAX = float(np.finfo(float).max)
"""What ``np.nan_to_num`` puts for an infinity (with its sign)."""
_NIS_FLOOR = 1e-6
"""Lower bound of a NIS in the attribution ratio (a perfect fix must not divide by zero)."""


@dataclass(frozen=True, slots=True)
class IntegrityConfig:
    """Settings of the integrity monitor (validated)."""

    false_alarm_prob: float = 1e-7
    """Per-test false-alarm probability of the fix-level tests (innovation, ellipsoid) and
    of the separation snapshot test. At 10 fixes/s this bounds the false alerts at
    3.6e-3 per hour per test even if every epoch were independent."""
    slope_false_alarm_prob: float = 1e-7
    """Per-test false-alarm probability of the separation slope test (S3, ramps)."""
    residual_false_alarm_prob: float = 1e-7
    """Per-test false-alarm probability of the separation residual test (S3, dithering)."""
    integrity_risk_horizontal: float = 5e-9
    """Allocated risk of the HPL; 5e-9 gives DO-229's K_H = 6.18."""
    integrity_risk_vertical: float = 1e-7
    """Allocated risk of the VPL; 1e-7 gives DO-229's K_V = 5.33."""
    separation_window_s: float = 10.0
    """Sliding window of the slope and residual tests: long enough that a 4 cm/s ramp
    rises well above the slope noise, short enough to be caught before it reaches 1 m."""
    min_window_points: int = 5
    """The window tests need at least this many separations (1 Hz GNSS: 5 s of data)."""
    pair_max_dt_s: float = 0.25
    """Two solutions are separated only when their times differ by at most this."""
    recovery_s: float = 10.0
    """An excluded receiver (or an unresolved fault) is cleared after this long without a
    failed test: one separation window, so the window no longer holds faulty data."""
    approach_category: ApproachCategory = ApproachCategory.CAT_I
    """The approach category the operator requires: its alert limits apply in approach
    and landing (NONE: the non-precision limits)."""
    report_rate_hz: float = 1.0
    """Rate of CMP_HPL / CMP_VPL / CMP_CAT and of the IntegrityReport (GNSS_INTEGRITY)."""
    category_upgrade_dwell_s: float = 5.0
    """A better available category is announced after holding this long (downgrades at once)."""
    attribution_error_prob: float = 1e-4
    """Probability that a consistent receiver is blamed for another's fault: with several
    receivers, a failed innovation test is pinned on one only if its NIS exceeds the
    others' by the F(dof, dof) quantile at this probability (659 for 3 dof)."""
    default_vel_var_m2ps2: float = 0.25
    """Velocity variance for extrapolating a paired fix whose velocity accuracy is unknown."""
    reference_max_age_s: float = 60.0
    """An inertial reference coasting longer than this since its anchor is not tested
    against: its covariance is only as right as the configured IMU grade, and an error
    there (a MEMS unit configured as tactical) grows with the coasting time until the
    reference blames a healthy receiver and, the references no longer re-anchoring while
    it is excluded, keeps it excluded for good. In normal flight slots are re-anchored
    every ``CoastConfig.life_s`` (30 s); older ones exist only after a fault, where this
    bounds how long a receiver stays excluded on the references' word alone (with a
    second receiver the pair test still holds a faulty one out)."""
    phase: PhaseConfig = field(default_factory=PhaseConfig)
    """Flight-phase rules."""

    def __post_init__(self) -> None:
        for name in (
            "false_alarm_prob",
            "slope_false_alarm_prob",
            "residual_false_alarm_prob",
            "integrity_risk_horizontal",
            "integrity_risk_vertical",
            "attribution_error_prob",
        ):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} must be in (0, 1)")
        for name in (
            "separation_window_s",
            "pair_max_dt_s",
            "recovery_s",
            "report_rate_hz",
            "default_vel_var_m2ps2",
            "reference_max_age_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0")
        dwell = self.category_upgrade_dwell_s
        if not (math.isfinite(dwell) and dwell >= 0.0):
            raise ValueError("category_upgrade_dwell_s must be finite and >= 0")
        if self.min_window_points < 3:
            raise ValueError("min_window_points must be >= 3")
        if not isinstance(self.approach_category, ApproachCategory):
            raise ValueError("approach_category must be an ApproachCategory")


@dataclass(slots=True)
class _Receiver:
    last_meas: GnssMeasurement | None = None
    excluded_until_s: float = -math.inf
    alerted: bool = False
    last_fail_t_s: float = -math.inf
    last_nis: float = 0.0
    """The navigator's last NIS for this receiver, per degree of freedom."""
    last_nis_t_s: float = -math.inf


@dataclass(frozen=True, slots=True)
class FixCheck:
    """The verdict of :meth:`IntegrityMonitor.on_fix` on the last fix (for callers and tests)."""

    t_s: float
    receiver_id: int
    failed: bool
    reasons: tuple[str, ...]
    culprits: tuple[int, ...]
    unresolved: bool


class IntegrityMonitor:
    """Fault detection and exclusion, solution separation and protection levels.

    See the module docstring. Attributes read by the engine: ``integrity_ok``,
    ``phase``, ``category``, ``levels`` (the last :class:`ProtectionLevels`),
    ``fault_detected``; ``stats`` counts every rejection by reason over the monitor's
    life (:meth:`reset` keeps it). Protection levels are ``math.inf`` when the
    solution covariance is not finite (then integrity is lost).
    """

    def __init__(self, config: IntegrityConfig | None = None) -> None:
        self.config = config or IntegrityConfig()
        cfg = self.config
        self.k_h = k_horizontal(cfg.integrity_risk_horizontal)
        self.k_v = k_vertical(cfg.integrity_risk_vertical)
        self._chi2_cache: dict[int, float] = {}
        # F(3, 3): the fix-level tests are 3-dof position tests
        self._f_ratio = float(f_dist.isf(cfg.attribution_error_prob, 3, 3))
        self.stats: Counter[str] = Counter()
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget everything (autopilot reboot)."""
        self._rx: dict[int, _Receiver] = {}
        self._pairs: dict[PairKey, SeparationTracker] = {}
        self._pair_last: dict[PairKey, SeparationResult] = {}
        self._pair_used: dict[PairKey, dict[int, float]] = {}
        self._ref_anchor: dict[PairKey, float] = {}
        self._episode_start_s: float | None = None
        """When the current disagreement between receivers was first detected (None: none)."""
        self._unresolved_until_s = -math.inf
        self._unresolved_alerted = False
        self._fault_sep_h_m = 0.0
        self._fault_sep_v_m = 0.0
        self._now_s: float | None = None
        self._phase_classifier = PhaseClassifier(self.config.phase)
        self.phase = FlightPhase.TAXI
        self.integrity_ok = False
        self._integrity_announced: bool | None = None
        self.category = ApproachCategory.NONE
        self._category_candidate = ApproachCategory.NONE
        self._category_candidate_since_s = -math.inf
        self.levels: ProtectionLevels | None = None
        self.limit: AlertLimit | None = None
        self.last_check: FixCheck | None = None
        self._report_tick = -1

    def exclude(self, receiver_id: int) -> bool:
        """True when ``receiver_id`` is currently excluded (do not fuse its fixes)."""
        rx = self._rx.get(receiver_id)
        if rx is None or self._now_s is None:
            return False
        return self._now_s < rx.excluded_until_s

    @property
    def fault_detected(self) -> bool:
        """True while a fault is unresolved or any receiver is excluded."""
        if self._now_s is None:
            return False
        if self._now_s < self._unresolved_until_s:
            return True
        return any(self._now_s < rx.excluded_until_s for rx in self._rx.values())

    @property
    def fault_unresolved(self) -> bool:
        """True while a detected fault is not attributed to an excluded receiver."""
        return self._now_s is not None and self._now_s < self._unresolved_until_s

    def accuracy_floor_m(self) -> tuple[float, float]:
        """Horizontal and vertical 1-sigma the published accuracies must not undercut, m.

        While a fault is unresolved, two solutions disagree by the largest failing
        separation seen and nothing says which is right: the published solution may be
        off by that much, so GPS_INPUT's accuracies widen to at least it. (0, 0) otherwise.
        """
        if not self.fault_unresolved:
            return 0.0, 0.0
        return self._fault_sep_h_m, self._fault_sep_v_m

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express stored fixes in the engine's new local frame (re-anchoring)."""
        rot = rotation_between_frames(old, new)
        for rx in self._rx.values():
            m = rx.last_meas
            if m is None:
                continue
            lat, lon, alt = old.ned_to_lla(m.pos_ned_m)
            rx.last_meas = GnssMeasurement(
                t_s=m.t_s,
                pos_ned_m=new.lla_to_ned(lat, lon, alt),
                pos_var_ned_m2=m.pos_var_ned_m2,
                vel_ned_mps=rot @ np.nan_to_num(m.vel_ned_mps),
                vel_var_ned_m2ps2=m.vel_var_ned_m2ps2,
                fix_type=m.fix_type,
                receiver_id=m.receiver_id,
            )
        for tracker in self._pairs.values():
            tracker.rotate(rot)

    # ------------------------------------------------------------------ per fix

    def on_fix(
        self,
        fix: GnssFix,
        meas: GnssMeasurement,
        update: GnssUpdate | None,
        predicted: NavState | None = None,
        references: Mapping[str, NavState] | None = None,
    ) -> list[Output]:
        """Test one fix; returns FAULT alerts (at the onset of a fault, not per fix).

        Parameters
        ----------
        fix : the receiver's fix (for the receiver id and the alert text).
        meas : the same fix in the local NED frame.
        update : what the navigator did with it (its innovation chi-square), or None
            when it was not offered (e.g. the receiver is excluded).
        predicted : the potential filter's (S0) prediction at the fix time, or None.
        references : independent solutions at (about) the fix time, by name.
        """
        t = meas.t_s
        rid = meas.receiver_id
        if not self._valid_meas(meas):
            self.stats["bad_measurement"] += 1
            log.warning("rx%d fix at t=%.2f s rejected: non-finite position or variance", rid, t)
            return []
        if self._now_s is None or t > self._now_s:
            self._now_s = t
        rx = self._rx.get(rid)
        if rx is None:
            rx = self._rx[rid] = _Receiver()
        reasons: list[str] = []
        culprits: set[int] = set()
        unresolved = False

        if rx.last_meas is not None and rx.last_meas.fix_type != meas.fix_type:
            self._restart_series(rid)
        sep_results = self._separations(meas, references)
        innov_failed, fix_reasons = self._fix_tests(meas, update, predicted)
        if update is not None and update.dof > 0 and math.isfinite(update.nis):
            rx.last_nis = update.nis / update.dof
            rx.last_nis_t_s = t
        if fix_reasons:
            reasons += fix_reasons
            if innov_failed and not self._innovation_culprit(rid, t, sep_results):
                unresolved = True
                reasons.append("the navigator disagrees with other receivers too")
            else:
                culprits.add(rid)
            if update is not None and update.fused:
                unresolved = True
                reasons.append("fused by the navigator")

        for key, res in sep_results.items():
            if not res.failed:
                continue
            reasons += [f"{key[0]}-{key[1]} {r}" for r in res.reasons]
            self._fault_sep_h_m = max(self._fault_sep_h_m, float(np.hypot(*res.sep_ned_m[:2])))
            self._fault_sep_v_m = max(self._fault_sep_v_m, abs(float(res.sep_ned_m[2])))
            if key[1].startswith(_REF):
                if rid in culprits or t < rx.excluded_until_s:
                    culprits.add(rid)  # already found faulty: it stays excluded
                elif update is None and self._other_receivers(rid, t):
                    # the reference was anchored from the navigator, which fuses another
                    # receiver: it may carry that one's fault; a disagreement, unresolved
                    self.stats["reference_vs_unfused"] += 1
                    unresolved = True
                    if self._episode_start_s is None:
                        self._episode_start_s = t
                elif self._ref_trusted(key):
                    culprits.add(rid)
                else:
                    self.stats["reference_untrusted"] += 1
                continue
            if self._episode_start_s is None:
                self._episode_start_s = t
            a, b = int(key[0][2:]), int(key[1][2:])
            culprit = self._arbitrate(a, b, key, culprits)
            if culprit is None:
                unresolved = True
            else:
                culprits.add(culprit)

        rx.last_meas = meas
        outputs: list[Output] = []
        for cid in sorted(culprits):
            outputs += self._exclude_receiver(cid, t, reasons)
        if unresolved:
            self.stats["unresolved"] += 1
            self._unresolved_until_s = t + self.config.recovery_s
            if not self._unresolved_alerted:
                self._unresolved_alerted = True
                text = f"unresolved: {'; '.join(reasons)}"
                outputs.append(Alert(t, AlertCode.FAULT, Severity.CRITICAL, text[:120]))
                log.warning("integrity fault unresolved at t=%.2f s: %s", t, text)
        elif t >= self._unresolved_until_s:
            self._unresolved_alerted = False
            self._fault_sep_h_m = self._fault_sep_v_m = 0.0
        if not reasons and t >= rx.excluded_until_s:
            rx.alerted = False
        if self._episode_start_s is not None and not self.fault_detected:
            self._episode_start_s = None
        self.last_check = FixCheck(
            t, rid, bool(reasons), tuple(reasons), tuple(sorted(culprits)), unresolved
        )
        return outputs

    def _other_receivers(self, rid: int, t: float) -> bool:
        """Is another receiver, not excluded, giving fixes (within one separation window)?"""
        horizon = self.config.separation_window_s
        return any(
            qid != rid
            and q.last_meas is not None
            and t - q.last_meas.t_s <= horizon
            and not t < q.excluded_until_s
            for qid, q in self._rx.items()
        )

    def _restart_series(self, rid: int) -> None:
        """Restart every separation series of receiver ``rid`` (its fix type changed).

        The window tests assume one error process over the window; a change of fix type
        (RTK fixed to float, float to 3-D, back) changes the receiver's error and its
        stated accuracy at once, a jump that is not a fault (as S3 keeps one satellite set
        per approach: a change causes jumps)."""
        tag = f"rx{rid}"
        for key, tracker in self._pairs.items():
            if tag in key:
                tracker.reset()
        self.stats["series_restarted_fix_type"] += 1

    def _valid_meas(self, meas: GnssMeasurement) -> bool:
        # on Python floats, not numpy reductions: this runs on every fix
        var = meas.pos_var_ned_m2.tolist()
        return (
            all(map(math.isfinite, meas.pos_ned_m.tolist()))
            and all(map(math.isfinite, var))
            and min(var) > 0.0
            and math.isfinite(meas.t_s)
        )

    def _chi2_threshold(self, dof: int) -> float:
        th = self._chi2_cache.get(dof)
        if th is None:
            th = float(chi2.isf(self.config.false_alarm_prob, dof))
            self._chi2_cache[dof] = th
        return th

    def _innovation_culprit(
        self, rid: int, t: float, this_epoch: Mapping[PairKey, SeparationResult]
    ) -> bool:
        """Is a failed innovation test of ``rid`` its own fault, not the navigator's?

        * Not while an earlier fault is unresolved: a navigator that fused a slowly
          growing fault makes the good receiver look faulty.
        * Not when this fix agrees (separation snapshot, ``this_epoch``) with another
          receiver's: then the navigator is what is off.
        * With no other receiver recently tested against the same navigator, yes.
        * Otherwise only when its NIS exceeds each other's by the F(dof, dof)
          quantile at ``attribution_error_prob``: a navigator pulled by a faulty
          receiver gives comparable innovations to all, and nothing tells which is
          wrong.
        """
        if self.fault_unresolved:
            return False  # the navigator may have absorbed the unresolved fault already
        mine = self._rx[rid].last_nis
        for qid, other in self._rx.items():
            if qid == rid:
                continue
            lo, hi = sorted((rid, qid))
            pair = this_epoch.get((f"rx{lo}", f"rx{hi}"))
            if pair is not None and not pair.snapshot_failed:
                return False  # it agrees with another receiver: the navigator is off
            if t - other.last_nis_t_s > self.config.pair_max_dt_s:
                continue
            if not mine > self._f_ratio * max(other.last_nis, _NIS_FLOOR):
                return False
        return True

    def _fix_tests(
        self, meas: GnssMeasurement, update: GnssUpdate | None, predicted: NavState | None
    ) -> tuple[bool, list[str]]:
        reasons: list[str] = []
        innov_failed = False
        if update is not None and update.dof > 0:
            if math.isfinite(update.nis):
                th = self._chi2_threshold(update.dof)
                if update.nis > th:
                    self.stats["fix_innovation"] += 1
                    innov_failed = True
                    reasons.append(f"innovation chi2 {update.nis:.1f} > {th:.1f}")
            else:
                self.stats["bad_update"] += 1
        if predicted is not None:
            dt = meas.t_s - predicted.t_s
            pred_pos = predicted.pos_ned_m + np.nan_to_num(predicted.vel_ned_mps) * dt
            innov = meas.pos_ned_m - pred_pos
            s_cov = predicted.pos_cov_ned_m2 + np.diag(meas.pos_var_ned_m2)
            try:
                stat = float(innov @ np.linalg.solve(s_cov, innov))
            except np.linalg.LinAlgError:
                self.stats["bad_prediction"] += 1
                return innov_failed, reasons
            if not math.isfinite(stat):
                self.stats["bad_prediction"] += 1
                return innov_failed, reasons
            th = self._chi2_threshold(3)
            if stat > th:
                self.stats["fix_ellipsoid"] += 1
                reasons.append(f"potential ellipsoid chi2 {stat:.1f} > {th:.1f}")
        return innov_failed, reasons

    def _tracker(self, key: PairKey) -> SeparationTracker:
        tracker = self._pairs.get(key)
        if tracker is None:
            cfg = self.config
            tracker = SeparationTracker(
                cfg.separation_window_s,
                cfg.min_window_points,
                cfg.false_alarm_prob,
                cfg.slope_false_alarm_prob,
                cfg.residual_false_alarm_prob,
            )
            self._pairs[key] = tracker
        return tracker

    def _separations(
        self, meas: GnssMeasurement, references: Mapping[str, NavState] | None
    ) -> dict[PairKey, SeparationResult]:
        """This fix's separations from the other receivers' latest fixes, then from the
        references, by pair key (only the pairs tested at this epoch)."""
        results: dict[PairKey, SeparationResult] = {}
        if len(self._rx) > 1:
            self._receiver_separations(meas, results)
        if references:
            self._reference_separations(meas, references, results)
        return results

    def _receiver_separations(
        self, meas: GnssMeasurement, results: dict[PairKey, SeparationResult]
    ) -> None:
        cfg = self.config
        t = meas.t_s
        rid = meas.receiver_id
        px, py, pz = meas.pos_ned_m.tolist()
        fix_var = meas.pos_var_ned_m2.tolist()
        default_vel_var = cfg.default_vel_var_m2ps2
        for qid, other in self._rx.items():
            m = other.last_meas
            if qid == rid or m is None:
                continue
            dt = t - m.t_s
            if not 0.0 <= dt <= cfg.pair_max_dt_s:
                continue
            lo, hi = sorted((rid, qid))
            key = (f"rx{lo}", f"rx{hi}")
            used = self._pair_used.setdefault(key, {})
            if m.t_s <= used.get(qid, -math.inf):
                continue  # each fix of the other receiver is paired once
            used[rid] = t
            used[qid] = m.t_s
            # the other fix carried by dt with its velocity, per axis in floats (3-vectors)
            vn, ve, vd = _nan_to_num(m.vel_ned_mps.tolist())
            vel_var = [
                v if math.isfinite(v) else default_vel_var for v in m.vel_var_ned_m2ps2.tolist()
            ]
            mn, me, md = m.pos_ned_m.tolist()
            sep = [px - (mn + vn * dt), py - (me + ve * dt), pz - (md + vd * dt)]
            if rid != lo:
                sep = [-sep[0], -sep[1], -sep[2]]
            other_var = m.pos_var_ned_m2.tolist()
            cov = np.diag([fix_var[i] + (other_var[i] + vel_var[i] * dt * dt) for i in range(3)])
            res = self._pair_update(key, t, np.array(sep), cov)
            if res is not None:
                results[key] = res

    def _reference_separations(
        self,
        meas: GnssMeasurement,
        references: Mapping[str, NavState],
        results: dict[PairKey, SeparationResult],
    ) -> None:
        cfg = self.config
        t = meas.t_s
        rid = meas.receiver_id
        r_fix = np.diag(meas.pos_var_ned_m2)
        px, py, pz = meas.pos_ned_m.tolist()
        tag = f"rx{rid}"
        for name, ref in references.items():
            dt = t - ref.t_s
            if abs(dt) > cfg.pair_max_dt_s:
                self.stats["reference_too_old"] += 1
                continue
            vn, ve, vd = _nan_to_num(ref.vel_ned_mps.tolist())
            rn, re, rd = ref.pos_ned_m.tolist()
            # the fix less the reference carried by dt, per axis in floats (3-vector)
            sep = np.array([px - (rn + vn * dt), py - (re + ve * dt), pz - (rd + vd * dt)])
            cov = r_fix + ref.pos_cov_ned_m2 + ref.vel_cov_ned_m2ps2 * dt * dt
            key = (tag, _REF + name)
            drift: ReferenceDrift | None = None
            if isinstance(ref, CoastState):
                if t - ref.anchor_t_s > cfg.reference_max_age_s:
                    self.stats["reference_coasted_too_long"] += 1
                    continue
                drift = self._coast_drift(key, ref, meas)
                if drift is None:
                    continue
            res = self._pair_update(key, t, sep, cov, drift)
            if res is not None:
                results[key] = res

    def _coast_drift(
        self, key: PairKey, ref: CoastState, meas: GnssMeasurement
    ) -> ReferenceDrift | None:
        """The drift of an inertial reference for the window tests; restarts the pair's
        series when the reference re-anchored. None (counted) when it is unusable."""
        anchor = ref.anchor_t_s
        if self._ref_anchor.get(key) != anchor:
            if key in self._ref_anchor:
                self.stats["reference_reanchored"] += 1
            self._ref_anchor[key] = anchor
            self._tracker(key).reset()
        acc_cov = ref.acc_cov_ned_m2ps4
        if acc_cov is None or not math.isfinite(ref.vrw_psd_m2ps3):
            self.stats["bad_reference"] += 1
            return None
        w = self.config.separation_window_s
        try:
            return ReferenceDrift(
                # the fix's variance plus the reference's velocity random walk integrated
                # over one window (an upper bound of its variance about the window's line)
                window_var_m2=meas.pos_var_ned_m2 + ref.vrw_psd_m2ps3 * w**3 / 3.0,
                vel_var_m2ps2=ref.vel_cov_ned_m2ps2.diagonal().copy(),
                acc_var_m2ps4=acc_cov.diagonal().copy(),
            )
        except ValueError as exc:
            self.stats["bad_reference"] += 1
            log.warning("reference %s at t=%.2f s skipped: %s", key[1], meas.t_s, exc)
            return None

    def _pair_update(
        self,
        key: PairKey,
        t: float,
        sep: FloatArray,
        cov: FloatArray,
        drift: ReferenceDrift | None = None,
    ) -> SeparationResult | None:
        try:
            res = self._tracker(key).update(t, sep, cov, drift)
        except ValueError as exc:
            self.stats["bad_separation"] += 1
            log.warning("separation %s-%s at t=%.2f s skipped: %s", key[0], key[1], t, exc)
            return None
        self._pair_last[key] = res
        if not res.reasons:
            return res
        for reason in ("slope", "residual", "separation"):
            if any(r.startswith(reason) for r in res.reasons):
                self.stats[f"separation_{reason}"] += 1
        return res

    def _ref_trusted(self, key: PairKey) -> bool:
        """May the reference of ``key`` blame a receiver?

        A reference anchored from the navigator while it fused a faulty receiver carries
        that receiver's fault: against the good receiver it fails. So while receivers
        disagree, a reference only counts if it was anchored at least one separation
        window before the disagreement was first detected (the window tests look back
        that far: the fault may have been present all that time). Without a receiver
        disagreement (one receiver), every reference counts.
        """
        start = self._episode_start_s
        anchor = self._ref_anchor.get(key)
        if start is None or anchor is None:
            return True
        return anchor <= start - self.config.separation_window_s

    def _arbitrate(self, a: int, b: int, key: PairKey, culprits: set[int]) -> int | None:
        """Which of two disagreeing receivers is faulty, or None when nothing tells.

        A receiver already blamed or excluded is the culprit. Otherwise each one's latest
        separations (within one separation window) from third solutions (other receivers,
        references) are scored by their largest test statistic over its threshold
        (snapshot, slope, residual): the culprit is the one that fails a test against a
        third solution (score > 1) while the other passes them all (score <= 1).
        """
        for cid in (a, b):
            if cid in culprits or self.exclude(cid):
                return cid
        now = self._now_s if self._now_s is not None else -math.inf
        horizon = self.config.separation_window_s
        score: dict[int, list[float]] = {a: [], b: []}
        for k, res in self._pair_last.items():
            if k == key or now - res.t_s > horizon:
                continue
            if k[1].startswith(_REF) and not self._ref_trusted(k):
                continue
            for cid in (a, b):
                other = b if cid == a else a
                if f"rx{cid}" in k and f"rx{other}" not in k:
                    score[cid].append(_score(res))
        if not score[a] or not score[b]:
            return None
        sa, sb = max(score[a]), max(score[b])
        if sa > 1.0 >= sb:
            return a
        if sb > 1.0 >= sa:
            return b
        return None

    def _exclude_receiver(self, rid: int, t: float, reasons: list[str]) -> list[Output]:
        rx = self._rx.setdefault(rid, _Receiver())
        rx.excluded_until_s = t + self.config.recovery_s
        rx.last_fail_t_s = t
        self.stats["fault_fixes"] += 1
        if rx.alerted:
            return []
        rx.alerted = True
        self.stats["fault_alerts"] += 1
        text = f"rx{rid} excluded: {'; '.join(reasons)}"
        log.warning("t=%.2f s: %s", t, text)
        return [Alert(t, AlertCode.FAULT, Severity.WARNING, text[:120])]

    # ------------------------------------------------------------------ per solution

    def on_solution(self, solution: NavSolution, landed: LandedState | None = None) -> list[Output]:
        """Phase, protection levels, alert limit and category for one published solution.

        Returns INTEGRITY / CAT alerts on changes, and at ``report_rate_hz`` the
        ``CMP_HPL``, ``CMP_VPL``, ``CMP_CAT`` values and an :class:`IntegrityReport`.
        """
        cfg = self.config
        t = solution.t_s
        if not math.isfinite(t):
            self.stats["bad_solution"] += 1
            log.warning("solution with non-finite time rejected")
            return []
        if self._now_s is None or t > self._now_s:
            self._now_s = t
        self.phase = self._phase_classifier.update(solution.alt_msl_m, solution.vel_ned_mps, landed)
        pl = protection_levels(solution.pos_cov_ned_m2, self.k_h, self.k_v)
        self.levels = pl
        limit = alert_limit(self.phase, cfg.approach_category)
        self.limit = limit
        problems: list[str] = []
        if solution.mode in (NavMode.LOST, NavMode.INIT):
            problems.append(f"navigation {solution.mode.value}")
        if pl.hpl_m > limit.hal_m:
            problems.append(f"HPL {pl.hpl_m:.1f} m > HAL {limit.hal_m:.1f} m")
        if pl.vpl_m > limit.val_m:
            problems.append(f"VPL {pl.vpl_m:.1f} m > VAL {limit.val_m:.1f} m")
        if self.fault_unresolved:
            problems.append("unresolved fault")
        self.integrity_ok = not problems
        outputs: list[Output] = []
        if self.integrity_ok != self._integrity_announced:
            first = self._integrity_announced is None
            self._integrity_announced = self.integrity_ok
            where = f"({self.phase.value}, {limit.name})"
            if not self.integrity_ok:
                self.stats["integrity_alerts"] += 1
                text = f"lost {where}: {'; '.join(problems)}"
                log.warning("t=%.2f s integrity %s", t, text)
                outputs.append(Alert(t, AlertCode.INTEGRITY, Severity.CRITICAL, text[:120]))
            elif not first:
                outputs.append(
                    Alert(
                        t,
                        AlertCode.INTEGRITY,
                        Severity.NOTICE,
                        f"restored {where}: HPL {pl.hpl_m:.1f} m VPL {pl.vpl_m:.1f} m",
                    )
                )
        outputs += self._category_update(t, pl)
        tick = math.floor(t * cfg.report_rate_hz + 1e-6)
        if tick > self._report_tick:
            self._report_tick = tick
            outputs += [
                NamedValue(t, "CMP_HPL", pl.hpl_m),
                NamedValue(t, "CMP_VPL", pl.vpl_m),
                NamedValue(t, "CMP_CAT", float(int(self.category))),
                IntegrityReport(t, pl.hpl_m, pl.vpl_m, self.integrity_ok, self.fault_detected),
            ]
        return outputs

    def _category_update(self, t: float, pl: ProtectionLevels) -> list[Output]:
        avail = (
            ApproachCategory.NONE
            if self.fault_unresolved
            else available_category(pl.hpl_m, pl.vpl_m, pl.h95_m, pl.v95_m)
        )
        if avail != self._category_candidate:
            self._category_candidate = avail
            self._category_candidate_since_s = t
        change = avail < self.category or (
            avail > self.category
            and t - self._category_candidate_since_s >= self.config.category_upgrade_dwell_s
        )
        if not change:
            return []
        old = self.category
        self.category = avail
        self.stats["category_changes"] += 1
        severity = Severity.WARNING if avail < old else Severity.NOTICE
        return [Alert(t, AlertCode.CAT, severity, f"{_cat_name(old)} -> {_cat_name(avail)}")]


def _nan_to_num(values: list[float]) -> list[float]:
    """``np.nan_to_num`` on a few floats: NaN to 0, +-inf to +-the largest float (exactly
    numpy's values, without a numpy call per fix)."""
    if all(map(math.isfinite, values)):
        return values
    return [
        v if math.isfinite(v) else 0.0 if math.isnan(v) else math.copysign(_FLOAT_MAX, v)
        for v in values
    ]


def _score(res: SeparationResult) -> float:
    """The largest of a separation's test statistics over their thresholds (> 1 fails)."""
    ratios = [res.snapshot_stat / res.snapshot_threshold, res.slope_ratio, res.rss_ratio]
    return max(r for r in ratios if math.isfinite(r))


def _cat_name(cat: ApproachCategory) -> str:
    return "none" if cat is ApproachCategory.NONE else cat.name.replace("_", " ")
