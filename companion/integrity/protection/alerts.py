"""The published solution's integrity: protection levels against the alert limit, alerts, reports.

:meth:`AlertState.update` runs for every published solution: flight phase
(:mod:`companion.integrity.protection.phase`), protection levels (HPL/VPL from
the covariance, :mod:`companion.integrity.protection.levels`), the alert limit
of the phase and required approach category
(:mod:`companion.integrity.protection.limits`), ``integrity_ok``, the available
approach category; ``CMP INTEGRITY`` / ``CMP CAT`` alerts on changes;
``CMP_HPL``, ``CMP_VPL``, ``CMP_CAT`` and an :class:`IntegrityReport` at
``report_rate_hz``. An unresolved fault (from fault detection and exclusion)
means no integrity and no category.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import replace

from companion.integrity.config import IntegrityConfig
from companion.integrity.protection.levels import (
    ProtectionLevels,
    k_horizontal,
    k_vertical,
    protection_levels,
)
from companion.integrity.protection.limits import (
    AlertLimit,
    ApproachCategory,
    FlightPhase,
    alert_limit,
    available_category,
)
from companion.integrity.protection.phase import PhaseClassifier
from companion.types import (
    Alert,
    AlertCode,
    IntegrityReport,
    LandedState,
    NamedValue,
    NavMode,
    NavSolution,
    Output,
    Severity,
)

log = logging.getLogger(__name__)


class AlertState:
    """Phase, protection levels, integrity and category of the published solution.

    Attributes: ``phase``, ``levels`` (the last :class:`ProtectionLevels`; ``math.inf``
    when the solution covariance is not finite, then integrity is lost), ``limit``
    (the last :class:`AlertLimit`), ``integrity_ok``, ``category`` (the announced
    available category), ``k_h`` / ``k_v`` (the K factors of the configured risks).
    ``stats`` (shared with the rest of the monitor) counts alerts and changes.
    """

    def __init__(self, config: IntegrityConfig, stats: Counter[str]) -> None:
        self.config = config
        self.stats = stats
        self.k_h = k_horizontal(config.integrity_risk_horizontal)
        self.k_v = k_vertical(config.integrity_risk_vertical)
        self.reset()

    def reset(self) -> None:
        """Forget the phase, the announcements and the category (autopilot reboot)."""
        self._phase_classifier = PhaseClassifier(self.config.phase)
        self.phase = FlightPhase.TAXI
        self.integrity_ok = False
        self._integrity_announced: bool | None = None
        self._ok_since_s = -math.inf
        """Since when integrity has held without a break (for the restore dwell)."""
        self.category = ApproachCategory.NONE
        self._category_candidate = ApproachCategory.NONE
        self._category_candidate_since_s = -math.inf
        self.levels: ProtectionLevels | None = None
        self.limit: AlertLimit | None = None
        self._report_tick = -1

    @property
    def field_elevation_msl_m(self) -> float | None:
        """The field elevation (configured or learned on the ground), m MSL; None unknown."""
        return self._phase_classifier.field_elevation_msl_m

    def update(
        self,
        solution: NavSolution,
        landed: LandedState | None,
        fault_unresolved: bool,
        fault_detected: bool,
        hpl_floor_m: float = 0.0,
    ) -> list[Output]:
        """Phase, protection levels, alert limit and category for one published solution
        (finite ``t_s``), given the fault detector's state at its time. ``hpl_floor_m``:
        the HPL is at least this (a held-out receiver contradicts the solution by it).

        Returns INTEGRITY / CAT alerts on changes, and at ``report_rate_hz`` the
        ``CMP_HPL``, ``CMP_VPL``, ``CMP_CAT`` values and an :class:`IntegrityReport`.
        """
        cfg = self.config
        t = solution.t_s
        self.phase = self._phase_classifier.update(
            solution.alt_msl_m, solution.vel_ned_mps, landed, t
        )
        pl = protection_levels(solution.pos_cov_ned_m2, self.k_h, self.k_v)
        if hpl_floor_m > pl.hpl_m:
            pl = replace(pl, hpl_m=hpl_floor_m)
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
        if fault_unresolved:
            problems.append("unresolved fault")
        was_ok = self.integrity_ok
        self.integrity_ok = not problems
        if self.integrity_ok and not was_ok:
            self._ok_since_s = t
        outputs: list[Output] = []
        announced = self._integrity_announced
        where = f"({self.phase.value}, {limit.name})"
        if not self.integrity_ok and announced is not False:
            # a loss at once, once: not again until a restoration was announced
            self._integrity_announced = False
            self.stats["integrity_alerts"] += 1
            text = f"lost {where}: {'; '.join(problems)}"
            log.warning("t=%.2f s integrity %s", t, text)
            outputs.append(Alert(t, AlertCode.INTEGRITY, Severity.CRITICAL, text[:120]))
        elif self.integrity_ok and announced is None:
            self._integrity_announced = True  # the first state: nothing was lost
        elif (
            self.integrity_ok
            and announced is False
            and t - self._ok_since_s >= cfg.integrity_restore_dwell_s
        ):
            # a restoration once it has held (a limit crossed back and forth is one loss)
            self._integrity_announced = True
            outputs.append(
                Alert(
                    t,
                    AlertCode.INTEGRITY,
                    Severity.NOTICE,
                    f"restored {where}: HPL {pl.hpl_m:.1f} m VPL {pl.vpl_m:.1f} m",
                )
            )
        outputs += self._category_update(t, pl, fault_unresolved)
        tick = math.floor(t * cfg.report_rate_hz + 1e-6)
        if tick > self._report_tick:
            self._report_tick = tick
            outputs += [
                NamedValue(t, "CMP_HPL", pl.hpl_m),
                NamedValue(t, "CMP_VPL", pl.vpl_m),
                NamedValue(t, "CMP_CAT", float(int(self.category))),
                IntegrityReport(t, pl.hpl_m, pl.vpl_m, self.integrity_ok, fault_detected),
            ]
        return outputs

    def _category_update(
        self, t: float, pl: ProtectionLevels, fault_unresolved: bool
    ) -> list[Output]:
        """The available category; a downgrade is announced at once, an upgrade after
        holding ``category_upgrade_dwell_s``."""
        avail = (
            ApproachCategory.NONE
            if fault_unresolved
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


def _cat_name(cat: ApproachCategory) -> str:
    return "none" if cat is ApproachCategory.NONE else cat.name.replace("_", " ")
