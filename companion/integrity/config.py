"""The integrity monitor's settings: the ``[integrity]`` block (and ``[integrity.phase]``).

One block configures both halves of the monitor: the fault detection and
exclusion (:mod:`companion.integrity.fde`: false-alarm probabilities, the
separation window, recovery) and the protection levels and alerts
(:mod:`companion.integrity.protection`: integrity risks, the required approach
category, report rate, flight-phase rules).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from companion.integrity.protection.limits import ApproachCategory
from companion.integrity.protection.phase import PhaseConfig
from companion.ranges import check_ranges, ranged


@dataclass(frozen=True, slots=True)
class IntegrityConfig:
    """Settings of the integrity monitor (validated)."""

    false_alarm_prob: float = ranged(1e-7, gt=0.0, lt=1.0)
    """Per-test false-alarm probability of the fix-level tests (innovation, ellipsoid) and
    of the separation snapshot test. At 10 fixes/s this bounds the false alerts at
    3.6e-3 per hour per test even if every epoch were independent."""
    slope_false_alarm_prob: float = ranged(1e-7, gt=0.0, lt=1.0)
    """Per-test false-alarm probability of the separation slope test (ramps; Kim, Walter
    and Powell)."""
    residual_false_alarm_prob: float = ranged(1e-7, gt=0.0, lt=1.0)
    """Per-test false-alarm probability of the separation residual test (dithering; Kim,
    Walter and Powell)."""
    integrity_risk_horizontal: float = ranged(5e-9, gt=0.0, lt=1.0)
    """Allocated risk of the HPL; 5e-9 gives DO-229's K_H = 6.18."""
    integrity_risk_vertical: float = ranged(1e-7, gt=0.0, lt=1.0)
    """Allocated risk of the VPL; 1e-7 gives DO-229's K_V = 5.33."""
    separation_window_s: float = ranged(10.0, gt=0.0)
    """Sliding window of the slope and residual tests: long enough that a 4 cm/s ramp
    rises well above the slope noise, short enough to be caught before it reaches 1 m."""
    min_window_points: int = ranged(5, ge=3)
    """The window tests need at least this many separations (1 Hz GNSS: 5 s of data)."""
    pair_max_dt_s: float = ranged(0.25, gt=0.0)
    """Two solutions are separated only when their times differ by at most this."""
    recovery_s: float = ranged(10.0, gt=0.0)
    """An excluded receiver (or an unresolved fault) is cleared after this long without a
    failed test: one separation window, so the window no longer holds faulty data."""
    approach_category: ApproachCategory = ApproachCategory.CAT_I
    """The approach category the operator requires: its alert limits apply in approach
    and landing (NONE: the non-precision limits)."""
    report_rate_hz: float = ranged(1.0, gt=0.0)
    """Rate of CMP_HPL / CMP_VPL / CMP_CAT and of the IntegrityReport (GNSS_INTEGRITY)."""
    category_upgrade_dwell_s: float = ranged(5.0, ge=0.0)
    """A better available category is announced after holding this long (downgrades at once)."""
    integrity_restore_dwell_s: float = ranged(5.0, ge=0.0)
    """Restored integrity is announced after holding this long (a loss at once): a
    protection level hovering about its limit is one ``INTEGRITY lost``, not a stream."""
    attribution_error_prob: float = ranged(1e-4, gt=0.0, lt=1.0)
    """Probability that a consistent receiver is blamed for another's fault: with several
    receivers, a failed innovation test is pinned on one only if its NIS exceeds the
    others' by the F(dof, dof) quantile at this probability (659 for 3 dof)."""
    default_vel_var_m2ps2: float = ranged(0.25, gt=0.0)
    """Velocity variance for extrapolating a paired fix whose velocity accuracy is unknown."""
    reference_max_age_s: float = ranged(60.0, gt=0.0)
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
    baro_reference: bool = True
    """Test each receiver's height against the barometer's, calibrated against trusted
    GNSS (the independent vertical solution one receiver lacks; snapshot, slope and
    residual tests over ``baro_window_s``). A disagreement leaves the fault unresolved:
    with one receiver nothing tells which of the two heights is wrong."""
    baro_window_s: float = ranged(20.0, gt=0.0)
    """Window of the barometer's slope and residual tests, s: the barometer's white noise
    (0.1-0.3 m) needs about 20 s at 10 Hz to tell a 4 cm/s ramp before it reaches 1 m."""
    baro_min_height_m: float = ranged(10.0, ge=0.0)
    """The barometer is not tested against below this height above the field, nor in the
    taxi phase: the ground effect (rotor or wing downwash on the static port) shifts it."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if not isinstance(self.approach_category, ApproachCategory):
            raise ValueError(
                f"approach_category must be an ApproachCategory, got {self.approach_category!r}"
            )
