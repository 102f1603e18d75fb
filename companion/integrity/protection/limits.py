"""Requirement tables: alert limits per flight phase and approach category.

Every row cites where its numbers come from. The monitor compares the
protection levels (:mod:`companion.integrity.protection.levels`) with the alert limit
of the current flight phase; in the approach and landing phases the limit is
the one of the approach category the operator requires (configuration), and
the *available* category (published as ``CMP_CAT``) is the best one whose
alert limits and 95 % accuracy the current solution meets.

Conventions: HAL / VAL are horizontal / vertical alert limits in metres
(``math.inf`` where a phase sets none); time to alert in seconds; the 95 %
accuracy figures are the ones a solution's covariance must meet for a category
to be called available.

References
----------
Grzegorzewski (2005), "Navigating by a position potential in 3-D" (RAIM
horizontal alert limits 555 m departure / 1850 m en-route and TMA / 550 m
approach and NPA; NATO MASPS for GPS: vertical alarm limit 5.4 m, time to alarm
2 s threshold / 1 s objective; ICAO: precision approach time-to-alarm 6 s, CAT
II/III 2 s). El-Mowafy (2005), RTK networks for precision approach with an
adaptive GPS/INS blend (95 % accuracy CAT I 17.1 m H / 4.1 m V, CAT II 5.2 /
1.7, CAT III 4.1 / 0.6). ICAO Annex 10 Vol. I,
Table 3.7.2.4-1 (APV / LPV-200: HAL 40 m, VAL 35 m; terminal TTA 15 s, NPA
TTA 10 s). ICAO Annex 10 Vol. I, Attachment D, GBAS approach service type D
(lateral alert limit 17 m at 200 ft) for the CAT II/III horizontal limit.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass


class FlightPhase(enum.Enum):
    """Flight phase, determined from the state (:mod:`companion.integrity.protection.phase`)."""

    TAXI = "taxi"
    TAKEOFF = "takeoff"
    ENROUTE = "enroute"
    APPROACH = "approach"
    LANDING = "landing"


class ApproachCategory(enum.IntEnum):
    """Approach category; the value is what ``CMP_CAT`` publishes (0 none, 1-3)."""

    NONE = 0
    CAT_I = 1
    CAT_II = 2
    CAT_III = 3


@dataclass(frozen=True, slots=True)
class AlertLimit:
    """One row of the requirement table.

    ``hal_m`` / ``val_m``: horizontal / vertical alert limits, m (``math.inf``:
    none). ``time_to_alert_s``: the longest a hazard may last before the alert
    (the threshold); ``time_to_alert_objective_s`` the objective where a source
    gives one. ``source`` names the document the row comes from.
    """

    name: str
    hal_m: float
    val_m: float
    time_to_alert_s: float
    time_to_alert_objective_s: float
    source: str


@dataclass(frozen=True, slots=True)
class AccuracyRequirement:
    """95 % position accuracy a category requires, m (horizontal, vertical)."""

    h95_m: float
    v95_m: float
    source: str


PHASE_LIMITS: dict[FlightPhase, AlertLimit] = {
    FlightPhase.TAXI: AlertLimit(
        "surface",
        math.inf,
        math.inf,
        math.inf,
        math.inf,
        "Grzegorzewski (2005): no integrity requirement for surface movement",
    ),
    FlightPhase.TAKEOFF: AlertLimit(
        "departure",
        555.0,
        math.inf,
        15.0,
        15.0,
        "Grzegorzewski (2005): RAIM HAL 555 m departure; "
        "ICAO Annex 10 Table 3.7.2.4-1 terminal TTA 15 s",
    ),
    FlightPhase.ENROUTE: AlertLimit(
        "en-route/TMA",
        1850.0,
        math.inf,
        15.0,
        15.0,
        "Grzegorzewski (2005): RAIM HAL 1850 m en-route and TMA; "
        "ICAO Annex 10 Table 3.7.2.4-1 terminal TTA 15 s",
    ),
    FlightPhase.APPROACH: AlertLimit(
        "NPA",
        550.0,
        math.inf,
        10.0,
        10.0,
        "Grzegorzewski (2005): RAIM HAL 550 m approach and NPA; "
        "ICAO Annex 10 Table 3.7.2.4-1 NPA TTA 10 s",
    ),
    FlightPhase.LANDING: AlertLimit(
        "NPA",
        550.0,
        math.inf,
        10.0,
        10.0,
        "Grzegorzewski (2005): RAIM HAL 550 m approach and NPA; "
        "ICAO Annex 10 Table 3.7.2.4-1 NPA TTA 10 s",
    ),
}
"""Alert limits per phase when no approach category is required (or outside approach)."""

CATEGORY_LIMITS: dict[ApproachCategory, AlertLimit] = {
    ApproachCategory.CAT_I: AlertLimit(
        "CAT I (LPV-200)",
        40.0,
        35.0,
        6.0,
        6.0,
        "ICAO Annex 10 Table 3.7.2.4-1 LPV-200 HAL 40 m / VAL 35 m; Grzegorzewski (2005): "
        "ICAO precision approach TTA 6 s",
    ),
    ApproachCategory.CAT_II: AlertLimit(
        "CAT II",
        17.0,
        5.4,
        2.0,
        1.0,
        "Grzegorzewski (2005): NATO MASPS VAL 5.4 m, TTA 2 s (1 s objective), ICAO CAT "
        "II/III TTA 2 s; "
        "HAL 17 m: ICAO Annex 10 Att. D GBAS GAST D lateral alert limit",
    ),
    ApproachCategory.CAT_III: AlertLimit(
        "CAT III",
        17.0,
        5.4,
        2.0,
        1.0,
        "Grzegorzewski (2005): NATO MASPS VAL 5.4 m, TTA 2 s (1 s objective), ICAO CAT "
        "II/III TTA 2 s; "
        "HAL 17 m: ICAO Annex 10 Att. D GBAS GAST D lateral alert limit",
    ),
}
"""Alert limits of the precision-approach categories (approach and landing phases)."""

CATEGORY_ACCURACY: dict[ApproachCategory, AccuracyRequirement] = {
    ApproachCategory.CAT_I: AccuracyRequirement(
        17.1, 4.1, "El-Mowafy (2005): CAT I 17.1 m H / 4.1 m V (95 %)"
    ),
    ApproachCategory.CAT_II: AccuracyRequirement(
        5.2, 1.7, "El-Mowafy (2005): CAT II 5.2 m H / 1.7 m V (95 %)"
    ),
    ApproachCategory.CAT_III: AccuracyRequirement(
        4.1, 0.6, "El-Mowafy (2005): CAT III 4.1 m H / 0.6 m V (95 %)"
    ),
}
"""95 % accuracy each category requires (what tells CAT III from CAT II)."""

APPROACH_PHASES = (FlightPhase.APPROACH, FlightPhase.LANDING)


def alert_limit(phase: FlightPhase, required: ApproachCategory) -> AlertLimit:
    """The alert limit that applies in ``phase`` when ``required`` is the approach category.

    In approach and landing a required precision category replaces the NPA row;
    elsewhere the phase row applies.

    References
    ----------
    See the module docstring for the source of each row.
    """
    if phase in APPROACH_PHASES and required is not ApproachCategory.NONE:
        return CATEGORY_LIMITS[required]
    return PHASE_LIMITS[phase]


def available_category(hpl_m: float, vpl_m: float, h95_m: float, v95_m: float) -> ApproachCategory:
    """The best approach category whose alert limits and 95 % accuracy are met.

    Parameters
    ----------
    hpl_m, vpl_m : horizontal / vertical protection levels, m.
    h95_m, v95_m : 95 % horizontal / vertical accuracy of the solution, m.

    Returns
    -------
    ApproachCategory
        ``NONE`` when even CAT I is not met (or a value is not finite).

    References
    ----------
    El-Mowafy (2005) accuracy table; Grzegorzewski (2005) and ICAO alert limits (module
    docstring).
    """
    best = ApproachCategory.NONE
    isfinite = math.isfinite
    if not (isfinite(hpl_m) and isfinite(vpl_m) and isfinite(h95_m) and isfinite(v95_m)):
        return best
    for cat in (ApproachCategory.CAT_I, ApproachCategory.CAT_II, ApproachCategory.CAT_III):
        lim = CATEGORY_LIMITS[cat]
        acc = CATEGORY_ACCURACY[cat]
        if hpl_m <= lim.hal_m and vpl_m <= lim.val_m and h95_m <= acc.h95_m and v95_m <= acc.v95_m:
            best = cat
        else:
            break
    return best
