"""The integrity monitor: fault detection and exclusion, then protection levels and alerts.

Two entry points, both pure (no I/O, no clock; time is the samples' ``t_s``):

* :meth:`IntegrityMonitor.on_fix` for every GNSS fix the navigator was offered:
  fault detection and exclusion (:class:`~companion.integrity.fde.detector.FaultDetector`:
  fix-level tests, solution separation against the other receivers and the
  independent references, attribution, exclusion of a faulty receiver or an
  unresolved fault).
* :meth:`IntegrityMonitor.on_solution` for every published solution: flight
  phase, protection levels, alert limit, ``integrity_ok`` and the available
  approach category with their alerts and reports
  (:class:`~companion.integrity.protection.alerts.AlertState`), given the fault
  detector's state.

The two share one clock (the latest time of a fix or a solution: exclusions and
faults expire by it) and one ``stats`` counter.

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (solution
separation, slope and residual tests); Grzegorzewski (2005), "Navigating by a
position potential in 3-D" (ellipsoid test of a new fix against the potential
prediction; alert limits); El-Mowafy (2005), RTK networks for precision approach
with an adaptive GPS/INS blend (requirement tables). RTCA DO-229 appendix J
(protection levels). ``docs/methods.md`` (the method), ``docs/architecture.md``
(where the engine calls it).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from collections.abc import Mapping

from companion.integrity.config import IntegrityConfig
from companion.integrity.fde.detector import FaultDetector, FixCheck
from companion.integrity.fde.fix_tests import FixTests
from companion.integrity.protection.alerts import AlertState
from companion.integrity.protection.levels import ProtectionLevels
from companion.integrity.protection.limits import AlertLimit, ApproachCategory, FlightPhase
from companion.integrity.spoof import SpoofConfig, SpoofMonitor
from companion.nav.baro import BaroReference
from companion.nav.frames import LocalFrame
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.types import (
    GnssFix,
    IntegrityReport,
    InterferenceState,
    LandedState,
    NamedValue,
    NavSolution,
    Output,
)

__all__ = ["FixCheck", "IntegrityConfig", "IntegrityMonitor"]

log = logging.getLogger(__name__)


class IntegrityMonitor:
    """Fault detection and exclusion, solution separation and protection levels.

    See the module docstring. Attributes read by the engine: ``integrity_ok``,
    ``phase``, ``category``, ``levels`` (the last :class:`ProtectionLevels`),
    ``fault_detected``; ``stats`` counts every rejection by reason over the monitor's
    life (:meth:`reset` keeps it). Protection levels are ``math.inf`` when the
    solution covariance is not finite (then integrity is lost).
    """

    def __init__(
        self, config: IntegrityConfig | None = None, spoof: SpoofConfig | None = None
    ) -> None:
        self.config = config or IntegrityConfig()
        self.stats: Counter[str] = Counter()
        self.fde = FaultDetector(self.config, self.stats)
        """Fault detection and exclusion (per fix)."""
        self.spoof = SpoofMonitor(spoof)
        """Receivers moving unlike the IMU (a spoofer that tracks the vehicle), held out
        until they agree with it again (:mod:`companion.integrity.spoof`)."""
        self.protection = AlertState(self.config, self.stats)
        """Protection levels, integrity and category of the published solution."""
        self.k_h = self.protection.k_h
        self.k_v = self.protection.k_v
        self._excused_until_s: dict[int | None, float] = {}
        """Per receiver (None: every one), until when its fix-level failures are the
        service's own doing (:meth:`service_changed`)."""
        self._excuse_tests = FixTests(self.config.false_alarm_prob, Counter())
        """The fix-level tests run again on an excused fix (their own counters)."""

    def reset(self) -> None:
        """Forget everything but ``stats`` (autopilot reboot)."""
        self.fde.reset()
        self.protection.reset()
        self.spoof.reset()
        self._excused_until_s.clear()

    # ------------------------------------------------------------------ the service's own changes

    def service_changed(
        self,
        t_s: float,
        reason: str,
        receivers: list[int] | None = None,
        horizon_s: float | None = None,
        *,
        series: bool = True,
    ) -> None:
        """The service changed itself at ``t_s`` (``reason``, for the log: the lag it places
        a receiver's fixes with, a reset of the navigator, its IMU grade ...).

        What the change invalidates is re-seeded: the separation series of ``receivers``
        (None: every receiver) start again and forget their latest results (unless
        ``series`` is False: a change of the navigator alone leaves the receivers'
        comparisons with each other valid), and their innovation memory is cleared
        (:meth:`FaultDetector.reseed`). Until ``t_s +
        horizon_s`` (default: one separation window, the series' memory) a failed
        fix-level test of theirs (the navigator's innovation, the potential filter's
        ellipsoid) is not attributed to the receiver: counted (``self_change_excused``),
        logged, and the fix tested as if the navigator had not been offered it. The
        separation tests run on: their series hold only what came after the change.
        """
        self.fde.reseed(receivers, series=series)
        horizon = self.config.separation_window_s if horizon_s is None else horizon_s
        keys: list[int | None] = [None] if receivers is None else list(receivers)
        for key in keys:
            until = max(self._excused_until_s.get(key, -math.inf), t_s + horizon)
            self._excused_until_s[key] = until
        self.stats["self_changes"] += 1
        log.info("t=%.2f s service changed itself (%s): tests re-seeded", t_s, reason)

    def _excused(self, receiver_id: int, t_s: float) -> bool:
        until = self._excused_until_s
        return t_s < until.get(receiver_id, -math.inf) or t_s < until.get(None, -math.inf)

    # ------------------------------------------------------------------ fault detection

    def exclude(self, receiver_id: int) -> bool:
        """True when ``receiver_id`` is currently excluded (do not fuse its fixes): by fault
        detection, or held out as spoofed."""
        return self.fde.exclude(receiver_id) or self.spoof.excluded(receiver_id)

    def shown_wrong(self, receiver_id: int) -> bool:
        """True while ``receiver_id`` is excluded on independent evidence (another
        receiver, a reference, the IMU's drag test): the navigator must not be reset to it
        on its own self-consistency."""
        return self.fde.shown_wrong(receiver_id) or self.spoof.excluded(receiver_id)

    @property
    def fault_detected(self) -> bool:
        """True while a fault is unresolved, any receiver is excluded or one is held out
        as spoofed."""
        return self.fde.fault_detected or bool(self.spoof.episodes)

    @property
    def fault_unresolved(self) -> bool:
        """True while a detected fault is not attributed to an excluded receiver."""
        return self.fde.fault_unresolved

    @property
    def last_check(self) -> FixCheck | None:
        """The verdict on the last fix."""
        return self.fde.last_check

    def accuracy_floor_m(self) -> tuple[float, float]:
        """Horizontal and vertical 1-sigma the published accuracies must not undercut, m:
        an unresolved fault's (:meth:`FaultDetector.accuracy_floor_m`) or a receiver held
        out as spoofed (:meth:`SpoofMonitor.accuracy_floor_m`)."""
        h_m, v_m = self.fde.accuracy_floor_m()
        return max(h_m, self.spoof.accuracy_floor_m()), v_m

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express stored fixes in the engine's new local frame (re-anchoring)."""
        self.fde.shift_frame(old, new)

    def on_fix(
        self,
        fix: GnssFix,
        meas: GnssMeasurement,
        update: GnssUpdate | None,
        predicted: NavState | None = None,
        references: Mapping[str, NavState] | None = None,
        baro: BaroReference | None = None,
    ) -> list[Output]:
        """Test one fix; returns FAULT alerts (parameters: :meth:`FaultDetector.on_fix`).

        ``baro`` is used only when :meth:`baro_usable` (its series restart otherwise)."""
        if baro is not None and not self.baro_usable(baro):
            baro = None
        if baro is None:
            self.fde.pairs.restart_baro()
        if (update is not None or predicted is not None) and self._excused(
            fix.receiver_id, meas.t_s
        ):
            _, failures = self._excuse_tests.run(meas, update, predicted)
            if failures:
                self.stats["self_change_excused"] += 1
                log.info(
                    "t=%.2f s rx%d: %s, after a change of the service's own: not attributed",
                    meas.t_s,
                    fix.receiver_id,
                    "; ".join(failures),
                )
                update, predicted = None, None
        outputs = self.fde.on_fix(fix, meas, update, predicted, references, baro)
        if outputs and self.spoof.excluded(fix.receiver_id):
            # the receiver is held out as spoofed, said once by SPOOF: its tests' failures
            # meanwhile are that same event (counted, not alerted again)
            self.stats["fault_alerts_while_spoofed"] += len(outputs)
            return []
        return outputs

    def baro_usable(self, baro: BaroReference) -> bool:
        """Is the barometer tested against now? ``baro_reference`` on, out of the taxi
        phase and, with a field elevation known, at least ``baro_min_height_m`` above the
        field (the ground effect). Counted ``baro_not_used_*`` when not."""
        cfg = self.config
        if not cfg.baro_reference:
            return False
        if self.protection.phase is FlightPhase.TAXI:
            self.stats["baro_not_used_ground"] += 1
            return False
        field_m = self.protection.field_elevation_msl_m
        if field_m is not None and baro.alt_msl_m - field_m < cfg.baro_min_height_m:
            self.stats["baro_not_used_low"] += 1
            return False
        return True

    # ------------------------------------------------------------------ protection

    @property
    def phase(self) -> FlightPhase:
        """The flight phase of the last published solution."""
        return self.protection.phase

    @property
    def integrity_ok(self) -> bool:
        """Whether the last published solution had integrity."""
        return self.protection.integrity_ok

    @property
    def category(self) -> ApproachCategory:
        """The announced available approach category."""
        return self.protection.category

    @property
    def levels(self) -> ProtectionLevels | None:
        """The last protection levels (None before the first solution)."""
        return self.protection.levels

    @property
    def limit(self) -> AlertLimit | None:
        """The last alert limit (None before the first solution)."""
        return self.protection.limit

    def on_solution(self, solution: NavSolution, landed: LandedState | None = None) -> list[Output]:
        """Phase, protection levels, alert limit and category for one published solution.

        Returns INTEGRITY / CAT alerts on changes, and at ``report_rate_hz`` the
        ``CMP_HPL``, ``CMP_VPL``, ``CMP_CAT`` values and an :class:`IntegrityReport`
        (:meth:`AlertState.update`).
        """
        t = solution.t_s
        if not math.isfinite(t):
            self.stats["bad_solution"] += 1
            log.warning("solution with non-finite time rejected")
            return []
        fde = self.fde
        fde.advance(t)
        outputs = self.protection.update(
            solution,
            landed,
            fde.fault_unresolved,
            self.fault_detected,
            hpl_floor_m=self.spoof.hpl_floor_m(),
        )
        state = self.spoof.state()
        if not any(isinstance(out, IntegrityReport) for out in outputs):
            return outputs
        verified = self.spoof.verified_mps2()
        if math.isfinite(verified):  # at the report's rate: what the drag test can see
            outputs = [*outputs, NamedValue(t, "CMP_SPF_A", verified)]
        if state is InterferenceState.UNKNOWN:
            return outputs
        return [
            dataclasses.replace(out, spoofing=state) if isinstance(out, IntegrityReport) else out
            for out in outputs
        ]
