"""Requirement tables and the available approach category."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.integrity.protection.levels import k_horizontal, k_vertical, protection_levels
from companion.integrity.protection.limits import (
    CATEGORY_ACCURACY,
    CATEGORY_LIMITS,
    PHASE_LIMITS,
    ApproachCategory,
    FlightPhase,
    alert_limit,
    available_category,
)


def test_every_row_cites_a_source_and_is_positive() -> None:
    rows = list(PHASE_LIMITS.values()) + list(CATEGORY_LIMITS.values())
    for row in rows:
        assert row.source
        assert row.hal_m > 0 and row.val_m > 0 and row.time_to_alert_s > 0
        assert row.time_to_alert_objective_s <= row.time_to_alert_s
    for acc in CATEGORY_ACCURACY.values():
        assert acc.source and acc.h95_m > 0 and acc.v95_m > 0
    assert set(PHASE_LIMITS) == set(FlightPhase)


def test_numbers_from_the_papers() -> None:
    cat2 = CATEGORY_LIMITS[ApproachCategory.CAT_II]
    assert cat2.val_m == 5.4 and cat2.time_to_alert_s == 2.0
    assert cat2.time_to_alert_objective_s == 1.0
    lpv = CATEGORY_LIMITS[ApproachCategory.CAT_I]
    assert (lpv.hal_m, lpv.val_m, lpv.time_to_alert_s) == (40.0, 35.0, 6.0)
    assert PHASE_LIMITS[FlightPhase.ENROUTE].hal_m == 1850.0
    assert PHASE_LIMITS[FlightPhase.TAKEOFF].hal_m == 555.0
    assert PHASE_LIMITS[FlightPhase.APPROACH].hal_m == 550.0
    assert CATEGORY_ACCURACY[ApproachCategory.CAT_III].v95_m == 0.6


def test_alert_limit_uses_the_required_category_only_on_approach() -> None:
    req = ApproachCategory.CAT_II
    assert alert_limit(FlightPhase.APPROACH, req) is CATEGORY_LIMITS[req]
    assert alert_limit(FlightPhase.LANDING, req) is CATEGORY_LIMITS[req]
    assert alert_limit(FlightPhase.ENROUTE, req) is PHASE_LIMITS[FlightPhase.ENROUTE]
    assert alert_limit(FlightPhase.APPROACH, ApproachCategory.NONE).hal_m == 550.0
    assert math.isinf(alert_limit(FlightPhase.TAXI, req).hal_m)


@pytest.mark.parametrize(
    ("sigma_h", "sigma_v", "expected"),
    [
        (0.015, 0.03, ApproachCategory.CAT_III),  # RTK fixed
        (0.2, 0.5, ApproachCategory.CAT_II),  # RTK float: v95 0.98 m > 0.6 m, VPL 2.7 m
        (0.5, 1.0, ApproachCategory.CAT_I),  # DGPS: VPL 5.33 m < 5.4 but v95 1.96 m > 1.7
        (2.5, 4.0, ApproachCategory.NONE),  # 3-D fix: v95 7.8 m > 4.1 m
        (0.5, 2.0, ApproachCategory.CAT_I),  # VPL 10.7 m > VAL 5.4 m
    ],
)
def test_available_category_from_covariance(
    sigma_h: float, sigma_v: float, expected: ApproachCategory
) -> None:
    cov = np.diag([sigma_h**2, sigma_h**2, sigma_v**2])
    pl = protection_levels(cov, k_horizontal(5e-9), k_vertical(1e-7))
    assert available_category(pl.hpl_m, pl.vpl_m, pl.h95_m, pl.v95_m) is expected


def test_available_category_of_non_finite_levels_is_none() -> None:
    assert available_category(math.inf, 1.0, 1.0, 1.0) is ApproachCategory.NONE
    assert available_category(1.0, math.nan, 1.0, 1.0) is ApproachCategory.NONE
