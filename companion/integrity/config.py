"""The integrity monitor's settings: the ``[integrity]`` block (and ``[integrity.phase]``).

One block configures both halves of the monitor: the fault detection and
exclusion (:mod:`companion.integrity.fde`: false-alarm probabilities, the
separation window, recovery) and the protection levels and alerts
(:mod:`companion.integrity.protection`: integrity risks, the required approach
category, report rate, flight-phase rules).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from companion.integrity.protection.limits import ApproachCategory
from companion.integrity.protection.phase import PhaseConfig


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
