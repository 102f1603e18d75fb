"""Taxi heading correction from the GNSS track (S4).

A fast INS alignment leaves an azimuth error of about a degree. On the ground,
on straight taxi sections, the track angle of the GNSS velocity equals the
true heading (up to an airframe constant), so the mean mismatch between the
INS heading and the GNSS track over many cycles is the heading error.

Each GNSS fix is one S4 *cycle*. A cycle counts only when

* the vehicle is on the ground (the autopilot's EXTENDED_SYS_STATE when it is
  sent; otherwise inferred here from the height above the ground reference,
  the climb rate and the ground speed, see :meth:`HeadingCorrector.on_ground`),
* the section is straight: the INS heading rate stayed at or below
  ``max_turn_rate_dps`` for the last ``settle_time_s`` (a turn ends a leg; the
  turn's cycles and the settling ones after it, while the receiver's velocity
  filter catches up, are not used; legs accumulate),
* the GNSS ground speed is between ``min_speed_mps`` and ``max_speed_mps``,
* the fix is at least ``min_fix_type`` and its velocity accuracy is at most
  ``max_vel_acc_mps``.

The INS heading is the :class:`~companion.types.AttitudeSample` yaw
interpolated (angle-aware) at the fix's time of validity ``fix.t_s``: GNSS is
delayed, so a few seconds of attitude are buffered.

Per cycle (S4)::

    dphi_i = psi_ins,i - atan2(V_E,i, V_N,i) - crab         (wrapped to +-180 deg)
    mean_i = mean_{i-1} + (dphi_i - mean_{i-1}) / i
    var_i  = var_{i-1} (i-2)/(i-1) + (dphi_i - mean_{i-1})^2 / i
    eps_i  = z_{95} sqrt(var_i / (i-1))                     (z_{95} = 1.96)

The correction is the mean mismatch: the corrected heading is
``psi_ins - mean``. A ground crab angle (heading minus track on a straight
taxi: nose-wheel toe, an antenna/IMU installation offset) is an airframe
constant. Unless it is given as ``ground_crab_deg`` it is *included* in the
correction, and the corrected heading is then the track direction, not the
fuselage axis.

Acceptance, evaluated once the sample is sufficient (``eps <= eps_limit_deg``
and at least ``min_cycles`` cycles):

* **park check**: before the taxi, the GNSS velocity while parked (speed at
  or below ``park_speed_mps`` for ``park_time_s``) must show no bias;
* **spread of the running mean** ``sigma[mean] <= mean_spread_limit_deg``
  (the same recursion applied to the running mean, over the cycles from
  ``spread_start_cycle`` on);
* **normality** of the mismatch (D'Agostino-Pearson, ``scipy.stats.normaltest``)
  on the mismatches standardised by their expected per-cycle sigma, so that
  legs at different speeds do not make a scale mixture look heavy-tailed;
* **dispersion**: the observed scatter against the expected sum of the GNSS
  track-angle variance ``(vel_acc / speed)^2`` and the INS course variance
  (one-sided chi-square test: a larger scatter than the sensors explain means
  something unmodelled, such as a changing crab angle);
* **stationarity** (additions to S4, aimed at its "changing crab angle" and
  "biased GNSS velocity" failure modes): no significant trend of the mismatch
  in time and no significant difference between legs (a velocity bias makes
  the mismatch depend on the track direction), each only when the change is
  also larger than ``max_drift_deg``.

All pass: ``CMP HDG_READY <value> ±<eps> n=<cycles>``; the correction is applied
on confirmation (:meth:`HeadingCorrector.apply`) or automatically
(``auto_apply``), announced with ``HDG_APPLIED``. Any fails:
``CMP HDG_REJECT <reason>`` and the accumulation starts over.

Accuracy limits (measured by ``bench/heading.py``): with the Doppler track the
cycles needed for ``eps`` grow as ``(1.96 vel_noise / (speed eps))^2``, e.g.
0.05 m/s of noise at 10 m/s needs about 140 cycles (14 s at 10 Hz) for
0.05 deg, 0.1 m/s at 5 m/s about 2 000 (200 s), 0.2 m/s at 3 m/s about
22 000. ``track_source="position"`` (the displacement over ``pos_baseline_s``
of RTK fixed positions) removes that limit. Either way
the correction is the INS heading error *averaged over the cycles*: if the
autopilot's own heading wanders, the corrected heading inherits the wander.

Fallback ground inference is weak when the service starts in flight without
EXTENDED_SYS_STATE (the first fix then sets the ground reference): slow level
flight below ``max_speed_mps`` would be taken for taxiing. The engine should
pass the landed state whenever the autopilot sends it.

Pure: no I/O, no clock; time comes from the samples. The state survives a
service restart through :meth:`HeadingCorrector.to_state` /
:meth:`HeadingCorrector.from_state` (plain JSON-compatible dicts).

References
----------
S4 (Markelov et al.), INS course correction from satellite navigation before
take-off: the mismatch, the recursive mean, variance and accuracy, the
straight-section rules and the acceptance criteria. The position track, the
trend and leg tests and the standardised normality test are this module's
additions.
"""

from __future__ import annotations

import bisect
import enum
import logging
import math
from collections import Counter
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats

from companion.nav.earth import radii_of_curvature_m
from companion.nav.rotations import wrap_pi
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    FixType,
    GnssFix,
    HeadingCommand,
    NamedValue,
    Output,
    Severity,
    VfrHudSample,
)

logger = logging.getLogger(__name__)

STATE_VERSION = 1
"""Version of the :meth:`HeadingCorrector.to_state` dictionary layout."""


TRACK_SOURCES = ("auto", "velocity", "position")
"""Allowed :attr:`HeadingConfig.track_source` values."""

RATE_BASELINE_S = 0.5
"""Baseline of the finite-difference heading rate, s: long enough that 0.01 deg of
heading noise stays far below the 1 deg/s turn limit."""


@dataclass(frozen=True, slots=True)
class HeadingConfig:
    """Settings of the taxi heading correction (S4).

    Attributes
    ----------
    min_speed_mps
        Lowest GNSS ground speed of a counted cycle, m/s. S4 used 6 m/s. The
        default 2.5 m/s (about 5 kt) is reached by every straight taxi (light
        aircraft and UAVs taxi at 5-15 kt, airliners at 15-20 kt) and stays
        above apron manoeuvring and pushback, where nose-wheel steering makes
        track and heading differ. The track-angle noise grows as
        ``vel_acc / speed``; the accuracy ``eps`` accounts for it.
    max_speed_mps
        Highest ground speed of a counted cycle, m/s: above it the vehicle is
        on its take-off or landing run, not taxiing.
    max_turn_rate_dps
        INS heading rate above which the vehicle is turning, deg/s (S4: 1).
    settle_time_s
        How long the heading rate must have stayed below the limit before a
        cycle counts, s: covers the receiver's velocity filter lag after a turn.
    receiver_id
        The GNSS receiver whose fixes make the cycles (another receiver's
        fixes are counted and ignored: two receivers would double-count).
    min_fix_type
        Worst GNSS fix type accepted.
    max_vel_acc_mps
        Worst GNSS velocity accuracy (1 sigma) accepted, m/s.
    default_vel_acc_mps
        Velocity accuracy (1 sigma, m/s) assumed when the receiver does not report one.
    vel_acc_floor_mps
        Floor applied to reported velocity accuracies, m/s (receivers round
        small accuracies down, some to zero).
    ins_yaw_noise_deg
        1-sigma cycle-to-cycle noise of the INS heading, deg (the INS course
        dispersion of the S4 dispersion criterion).
    track_source
        Where the GNSS track angle of a cycle comes from. ``"velocity"`` (S4):
        ``atan2(V_E, V_N)`` of each fix's velocity. ``"position"`` (an
        extension): the direction of the displacement between two fixes
        ``pos_baseline_s`` apart on the same straight leg, one cycle per
        baseline (non-overlapping, so that cycles stay independent). With RTK
        positions (millimetre-to-centimetre noise between epochs) it is one to
        two orders of magnitude less noisy than the Doppler velocity at taxi
        speeds; with a 3D fix it is worse. The S4 recursions and criteria are
        the same. ``"auto"`` (the default): the position track while the fixes
        are at least ``pos_min_fix_type``, the velocity track otherwise; the
        source is chosen at the first cycle of a sample, and a position-track
        sample that loses RTK starts over on the velocity track (never a mix).
    pos_baseline_s
        Time between the two fixes of a position track, s.
    pos_diff_sigma_m
        1-sigma per-axis error of the difference of two positions
        ``pos_baseline_s`` apart, m (the expected dispersion of a position track).
    pos_min_fix_type
        Worst fix type whose positions make a position track.
    ground_crab_deg
        Known airframe ground crab (heading minus track on a straight taxi),
        deg; removed from every mismatch. With 0 it is included in the correction.
    eps_limit_deg
        Sufficiency limit of the 95 % accuracy ``eps`` of the mean, deg (S4: 0.05).
    confidence
        Two-sided confidence of ``eps`` (S4: 0.95, i.e. 1.96 sigma).
    min_cycles
        Fewest velocity-track cycles before the sample is judged (the tests need
        a sample).
    pos_min_cycles
        The same for position-track cycles (one per ``pos_baseline_s``).
    max_cycles
        Cap on stored cycles (memory bound); beyond it the sample is judged as is.
    mean_spread_limit_deg
        Limit on the spread (1 sigma) of the running mean, deg (S4: 0.3).
    spread_start_cycle
        First cycle whose running mean enters the spread (the first running
        means are single noisy cycles); position track: ``pos_spread_start_cycle``.
    normality_alpha
        False-rejection probability of the normality test.
    dispersion_alpha
        False-rejection probability of the dispersion (chi-square) test.
    stationarity_alpha
        False-rejection probability of the trend and leg-consistency tests.
    max_drift_deg
        Smallest change of the mismatch (over the sample, or between leg means)
        worth rejecting, deg. The autopilot's own heading wanders by a few
        tenths of a degree over a minute on the ground (AHRS yaw stability; the
        project simulator models 0.2 deg 1-sigma with a 60 s correlation time),
        which a long sample always finds "significant": a smaller change is that
        wander, not a crab change or a velocity bias.
    min_leg_cycles
        Fewest cycles for a leg to enter the leg-consistency test.
    min_legs
        Fewest legs of at least ``min_leg_cycles`` before the sample is judged.
        S4 needs one. A GNSS velocity bias (or a crab angle) on a single
        heading is indistinguishable from a heading error; it shows as a
        difference between legs of different headings, so 2 makes the leg test
        mandatory (the parked check is the other guard).
    require_park_check
        Refuse READY unless a parked check passed (S4 does it first).
    park_speed_mps
        GNSS speed at or below which the vehicle is parked, m/s (S4: 0.2).
    park_time_s
        Parked time after which the GNSS velocity bias is checked, s (S4: 10-30).
    park_window_s
        Longest parked window used by the check (most recent), s.
    park_smooth_s
        The parked speed is that of the mean GNSS velocity over this time, s
        (a single noisy fix must not end the parking).
    park_max_bias_mps
        Largest tolerated GNSS velocity bias while parked, m/s.
    park_alpha
        False-rejection probability of the parked bias test.
    auto_apply
        Apply the correction as soon as it is READY, without a confirmation.
    publish_period_s
        Least time between two ``CMP_HDGC``/``CMP_HDGE`` publications, s (0: every fix).
    attitude_buffer_s
        Attitude history kept for interpolation at the fix time, s.
    max_attitude_gap_s
        Widest attitude gap interpolated across, s.
    max_extrapolation_s
        Furthest the attitude is extrapolated past its newest sample, s.
    ground_max_height_m
        Fallback ground inference: largest height above the ground reference, m.
    ground_max_climb_mps
        Fallback ground inference: largest climb rate magnitude (VFR_HUD), m/s.
    """

    min_speed_mps: float = 2.5
    max_speed_mps: float = 20.0
    max_turn_rate_dps: float = 1.0
    settle_time_s: float = 2.0
    receiver_id: int = 0
    min_fix_type: FixType = FixType.FIX_3D
    max_vel_acc_mps: float = 0.5
    default_vel_acc_mps: float = 0.1
    vel_acc_floor_mps: float = 0.02
    ins_yaw_noise_deg: float = 0.1
    track_source: str = "auto"
    pos_baseline_s: float = 1.0
    pos_diff_sigma_m: float = 0.01
    pos_min_fix_type: FixType = FixType.RTK_FIXED
    ground_crab_deg: float = 0.0
    eps_limit_deg: float = 0.05
    confidence: float = 0.95
    min_cycles: int = 100
    pos_min_cycles: int = 30
    max_cycles: int = 50_000
    mean_spread_limit_deg: float = 0.3
    spread_start_cycle: int = 20
    pos_spread_start_cycle: int = 10
    normality_alpha: float = 0.001
    dispersion_alpha: float = 0.001
    stationarity_alpha: float = 0.001
    max_drift_deg: float = 0.5
    min_leg_cycles: int = 20
    min_legs: int = 1
    require_park_check: bool = True
    park_speed_mps: float = 0.2
    park_time_s: float = 10.0
    park_window_s: float = 30.0
    park_smooth_s: float = 2.0
    park_max_bias_mps: float = 0.05
    park_alpha: float = 0.001
    auto_apply: bool = False
    publish_period_s: float = 1.0
    attitude_buffer_s: float = 5.0
    max_attitude_gap_s: float = 1.5
    max_extrapolation_s: float = 0.2
    ground_max_height_m: float = 15.0
    ground_max_climb_mps: float = 1.5

    def __post_init__(self) -> None:
        for name in ("min_fix_type", "pos_min_fix_type"):
            value = getattr(self, name)
            if not isinstance(value, FixType):
                try:  # a plain int from a config file
                    object.__setattr__(self, name, FixType(value))
                except (ValueError, TypeError) as exc:
                    raise ValueError(
                        f"HeadingConfig.{name} must be a FixType, got {value!r}"
                    ) from exc
        positive = (
            "min_speed_mps",
            "max_speed_mps",
            "max_turn_rate_dps",
            "max_vel_acc_mps",
            "default_vel_acc_mps",
            "vel_acc_floor_mps",
            "eps_limit_deg",
            "mean_spread_limit_deg",
            "max_drift_deg",
            "park_speed_mps",
            "park_time_s",
            "park_window_s",
            "park_smooth_s",
            "pos_baseline_s",
            "pos_diff_sigma_m",
            "park_max_bias_mps",
            "attitude_buffer_s",
            "max_attitude_gap_s",
            "ground_max_height_m",
            "ground_max_climb_mps",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"HeadingConfig.{name} must be finite and > 0, got {value!r}")
        non_negative = (
            "settle_time_s",
            "ins_yaw_noise_deg",
            "publish_period_s",
            "max_extrapolation_s",
        )
        for name in non_negative:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"HeadingConfig.{name} must be finite and >= 0, got {value!r}")
        if not math.isfinite(self.ground_crab_deg) or abs(self.ground_crab_deg) > 45.0:
            raise ValueError(
                "HeadingConfig.ground_crab_deg must be within +-45 deg, "
                f"got {self.ground_crab_deg!r}"
            )
        for name in ("confidence",):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"HeadingConfig.{name} must be in (0, 1), got {value!r}")
        for name in ("normality_alpha", "dispersion_alpha", "stationarity_alpha", "park_alpha"):
            value = getattr(self, name)
            if not 0.0 < value < 0.5:
                raise ValueError(f"HeadingConfig.{name} must be in (0, 0.5), got {value!r}")
        if self.max_speed_mps <= self.min_speed_mps:
            raise ValueError(
                "HeadingConfig.max_speed_mps must exceed min_speed_mps, "
                f"got {self.max_speed_mps!r} <= {self.min_speed_mps!r}"
            )
        if self.park_speed_mps >= self.min_speed_mps:
            raise ValueError(
                "HeadingConfig.park_speed_mps must be below min_speed_mps, "
                f"got {self.park_speed_mps!r} >= {self.min_speed_mps!r}"
            )
        if self.park_window_s < self.park_time_s:
            raise ValueError(
                "HeadingConfig.park_window_s must be >= park_time_s, "
                f"got {self.park_window_s!r} < {self.park_time_s!r}"
            )
        if self.min_cycles < 20:
            raise ValueError(f"HeadingConfig.min_cycles must be >= 20, got {self.min_cycles!r}")
        if self.max_cycles < self.min_cycles:
            raise ValueError(
                f"HeadingConfig.max_cycles must be >= min_cycles, got {self.max_cycles!r}"
            )
        if not 2 <= self.spread_start_cycle < self.min_cycles:
            raise ValueError(
                "HeadingConfig.spread_start_cycle must be in [2, min_cycles), "
                f"got {self.spread_start_cycle!r}"
            )
        if self.min_legs < 1:
            raise ValueError(f"HeadingConfig.min_legs must be >= 1, got {self.min_legs!r}")
        if self.min_leg_cycles < 3:
            raise ValueError(
                f"HeadingConfig.min_leg_cycles must be >= 3, got {self.min_leg_cycles!r}"
            )
        if self.attitude_buffer_s < self.settle_time_s + self.max_attitude_gap_s:
            raise ValueError(
                "HeadingConfig.attitude_buffer_s must cover settle_time_s + max_attitude_gap_s, "
                f"got {self.attitude_buffer_s!r}"
            )
        if self.track_source not in TRACK_SOURCES:
            raise ValueError(
                f"HeadingConfig.track_source must be one of {TRACK_SOURCES}, "
                f"got {self.track_source!r}"
            )
        if not 2 <= self.pos_spread_start_cycle < self.pos_min_cycles:
            raise ValueError(
                "HeadingConfig.pos_spread_start_cycle must be in [2, pos_min_cycles), "
                f"got {self.pos_spread_start_cycle!r}"
            )
        if self.pos_baseline_s > self.settle_time_s and self.track_source != "velocity":
            raise ValueError(
                "HeadingConfig.pos_baseline_s must not exceed settle_time_s (the straight "
                f"window must cover the baseline), got {self.pos_baseline_s!r}"
            )

    @property
    def z_score(self) -> float:
        """Two-sided normal quantile of ``confidence`` (1.96 for 95 %)."""
        return float(stats.norm.ppf(0.5 + 0.5 * self.confidence))


class HeadingPhase(enum.Enum):
    """Where the correction stands."""

    ACCUMULATING = "accumulating"  # collecting straight-leg cycles
    READY = "ready"  # all criteria hold: waiting for confirmation
    APPLIED = "applied"  # the correction is in use for this flight


@dataclass(frozen=True, slots=True)
class RunningStats:
    """S4 recursive mean and (n-1) variance of a scalar sequence.

    References
    ----------
    S4, the recursions for the mean ``mean_i = mean_{i-1} + (x_i - mean_{i-1})/i`` and
    the variance ``var_i = var_{i-1} (i-2)/(i-1) + (x_i - mean_{i-1})^2 / i``.
    """

    n: int = 0
    mean: float = 0.0
    var: float = 0.0

    def update(self, x: float) -> RunningStats:
        """Return the statistics with ``x`` added (S4 recursions)."""
        i = self.n + 1
        if i == 1:
            return RunningStats(1, x, 0.0)
        d = x - self.mean
        return RunningStats(i, self.mean + d / i, self.var * (i - 2) / (i - 1) + d * d / i)


@dataclass(frozen=True, slots=True)
class HeadingEstimate:
    """The current estimate, all angles in radians.

    ``correction_rad`` is the mean mismatch (INS heading minus GNSS track),
    ``sigma_rad`` the sample standard deviation of one mismatch, ``eps_rad`` the
    95 % accuracy of the mean (``inf`` below two cycles), ``n`` the cycles used,
    ``legs`` the straight legs they came from.
    """

    correction_rad: float
    sigma_rad: float
    eps_rad: float
    n: int
    legs: int


@dataclass(frozen=True, slots=True)
class Verdict:
    """Outcome of the acceptance criteria: ``reason`` is empty when all hold."""

    ok: bool
    reason: str
    details: dict[str, float]


def yaw_rate_radps(sample: AttitudeSample) -> float:
    """Heading (yaw) rate from the body rates, rad/s.

    ``psi_dot = (q sin(roll) + r cos(roll)) / cos(pitch)`` (ZYX Euler kinematics);
    NaN when the rates are not finite.
    """
    rate = sample.rate_b_radps
    if rate is None or len(rate) != 3:
        return math.nan
    q, r = float(rate[1]), float(rate[2])
    c_pitch = math.cos(sample.pitch_rad)
    if abs(c_pitch) < 1e-6:
        return math.nan
    return (q * math.sin(sample.roll_rad) + r * math.cos(sample.roll_rad)) / c_pitch


class HeadingCorrector:
    """Taxi heading correction (S4): a pure, stepwise estimator.

    Feed it :meth:`on_attitude` (INS heading and rate), :meth:`on_landed_state`
    (``on_ground`` from EXTENDED_SYS_STATE, ``None`` when not sent),
    :meth:`on_vfr_hud` (climb rate for the fallback ground inference) and
    :meth:`on_gnss` (one S4 cycle per fix). Outputs are returned, never sent.

    Publication: while accumulating, READY or APPLIED, every fix that leaves
    at least ``publish_period_s`` since the last publication yields
    ``NamedValue("CMP_HDGC", deg)`` (accumulating: the running mean; READY: the
    candidate; APPLIED: the applied correction) and ``NamedValue("CMP_HDGE", deg)``
    (its 95 % accuracy ``eps``), once there are two cycles. Alerts: HDG_READY,
    HDG_REJECT, HDG_APPLIED (:class:`~companion.types.Alert`).

    References
    ----------
    S4 (Markelov et al.), recursions and acceptance criteria (see module docstring).
    """

    def __init__(self, config: HeadingConfig | None = None) -> None:
        self.config = config if config is not None else HeadingConfig()
        self._z = self.config.z_score
        self._crab_rad = math.radians(self.config.ground_crab_deg)
        self._turn_rate_radps = math.radians(self.config.max_turn_rate_dps)
        self._ins_var_rad2 = math.radians(self.config.ins_yaw_noise_deg) ** 2
        # attitude buffer (not persisted: it is seconds long)
        self._att_t: list[float] = []
        self._att_yaw: list[float] = []
        self._att_turning: list[bool] = []
        self._att_rate: list[float] = []
        # ground state
        self._on_ground_explicit: bool | None = None
        self._climb_mps: float | None = None
        self._ground_ref_alt_m: float | None = None
        self._ground_ref_n = 0
        # accumulation
        self.phase = HeadingPhase.ACCUMULATING
        self._stats = RunningStats()
        self._mean_stats = RunningStats()
        self._t: list[float] = []
        self._x: list[float] = []
        self._sig: list[float] = []
        self._leg: list[int] = []
        self._leg_id = 0
        self._n_legs = 0
        self._leg_cycles = 0
        self._full_legs = 0
        self._in_leg = False
        # park check
        self._park_start_t: float | None = None
        self._park_vel: list[tuple[float, float, float]] = []  # (t, vn, ve)
        self._park_recent: list[tuple[float, float, float]] = []
        self._park_last_eval_t: float | None = None
        self._park_ok: bool | None = None
        self._park_reject_sent = False
        # results
        self._candidate: HeadingEstimate | None = None
        self._applied: HeadingEstimate | None = None
        self._last_publish_t: float | None = None
        self._last_fix_t: float | None = None
        self._pos_prev: tuple[float, float, float, int] | None = None
        self.rejections: Counter[str] = Counter()
        """Cycles or inputs not used, by reason (counted and logged)."""
        self.reject_alerts = 0
        self._source: str | None = None
        """Track source of the current sample ("position" / "velocity"; None: not chosen)."""

    # ------------------------------------------------------------------ inputs

    def on_attitude(self, sample: AttitudeSample) -> None:
        """Buffer the INS heading ``yaw_rad`` and its rate (turn detection)."""
        if not (math.isfinite(sample.t_s) and math.isfinite(sample.yaw_rad)):
            self._reject("attitude_not_finite")
            return
        if self._att_t and sample.t_s <= self._att_t[-1]:
            if sample.t_s < self._att_t[-1] - self.config.attitude_buffer_s:
                # the clock restarted (autopilot reboot): the old history is meaningless
                self._clear_attitude()
            else:
                self._reject("attitude_out_of_order")
                return
        rate = yaw_rate_radps(sample)
        diff_rate = self._yaw_diff_rate(sample)
        if not math.isfinite(rate):
            rate = diff_rate
        turning = (not math.isfinite(rate)) or abs(rate) > self._turn_rate_radps
        # also the heading change over the last RATE_BASELINE_S: catches a stream whose
        # body rates are missing or zero while the heading turns
        if math.isfinite(diff_rate) and abs(diff_rate) > self._turn_rate_radps:
            turning = True
        self._att_t.append(sample.t_s)
        self._att_yaw.append(wrap_pi(sample.yaw_rad))
        self._att_turning.append(turning)
        self._att_rate.append(rate if math.isfinite(rate) else 0.0)
        horizon = sample.t_s - self.config.attitude_buffer_s
        if len(self._att_t) > 64 and self._att_t[32] < horizon:
            k = bisect.bisect_left(self._att_t, horizon)
            del self._att_t[:k], self._att_yaw[:k], self._att_turning[:k], self._att_rate[:k]

    def _yaw_diff_rate(self, sample: AttitudeSample) -> float:
        """Heading rate from the heading change since the sample RATE_BASELINE_S earlier, rad/s."""
        if not self._att_t:
            return math.nan
        k = bisect.bisect_right(self._att_t, sample.t_s - RATE_BASELINE_S) - 1
        if k < 0:
            k = 0
        dt = sample.t_s - self._att_t[k]
        if dt <= 0.0 or dt > self.config.max_attitude_gap_s + RATE_BASELINE_S:
            return math.nan
        return wrap_pi(sample.yaw_rad - self._att_yaw[k]) / dt

    def on_landed_state(self, on_ground: bool | None) -> None:
        """The autopilot's landed state (EXTENDED_SYS_STATE); ``None``: not sent, infer it."""
        self._on_ground_explicit = on_ground

    def on_vfr_hud(self, sample: VfrHudSample) -> None:
        """Climb rate for the fallback ground inference."""
        if math.isfinite(sample.climb_mps):
            self._climb_mps = sample.climb_mps

    def on_command(self, command: HeadingCommand) -> list[Output]:
        """The ground station's answer: apply, or refuse (the sample is restarted)."""
        if command.apply:
            return self.apply(command.t_s)
        if self.phase is HeadingPhase.READY:
            logger.info("heading correction refused by the ground station")
            self._restart()
            self.reject_alerts += 1
            return [Alert(command.t_s, AlertCode.HDG_REJECT, Severity.WARNING, "refused")]
        self._reject("command_refuse_not_ready")
        return []

    def apply(self, t_s: float) -> list[Output]:
        """Apply the READY candidate (confirmation): ``HDG_APPLIED``; else nothing."""
        if self.phase is not HeadingPhase.READY or self._candidate is None:
            self._reject("apply_not_ready")
            return []
        self._applied = self._candidate
        self.phase = HeadingPhase.APPLIED
        text = self._format(self._applied)
        logger.info("heading correction applied: %s", text)
        return [Alert(t_s, AlertCode.HDG_APPLIED, Severity.NOTICE, text)]

    def on_gnss(self, fix: GnssFix) -> list[Output]:
        """One S4 cycle: park check, straight-leg test, recursions, criteria, publication."""
        out: list[Output] = []
        if not math.isfinite(fix.t_s):
            self._reject("fix_time_not_finite")
            return out
        if fix.receiver_id != self.config.receiver_id:
            self._reject("other_receiver")
            return out
        if self._last_fix_t is not None and fix.t_s <= self._last_fix_t:
            if fix.t_s < self._last_fix_t - self.config.attitude_buffer_s:
                self._last_fix_t = None  # the clock restarted (autopilot reboot)
            else:
                # a repeated or late fix (a receiver repeating its last solution) would
                # enter the sample twice
                self._reject("fix_not_newer")
                return out
        self._last_fix_t = fix.t_s
        vel = self._fix_velocity(fix)
        if vel is None:
            return out
        vn, ve = vel
        speed = math.hypot(vn, ve)
        on_ground = self.on_ground(fix, speed)
        if not on_ground:
            self._end_leg()
            self._park_reset()
            self._reject("not_on_ground")
        elif self.phase is HeadingPhase.ACCUMULATING:
            out.extend(self._park_step(fix, vn, ve, speed))
            self._cycle(fix, vn, ve, speed)
            out.extend(self._maybe_judge(fix.t_s))
        out.extend(self._publish(fix.t_s, on_ground))
        return out

    # ------------------------------------------------------------------ results

    @property
    def correction_rad(self) -> float:
        """The applied correction (rad), 0 until applied. Subtract it from the INS heading."""
        return self._applied.correction_rad if self._applied is not None else 0.0

    @property
    def applied(self) -> HeadingEstimate | None:
        """The applied estimate, ``None`` until applied."""
        return self._applied

    @property
    def candidate(self) -> HeadingEstimate | None:
        """The READY (or applied) estimate, ``None`` before READY."""
        return self._candidate

    @property
    def park_ok(self) -> bool | None:
        """Latest parked check: passed, failed, or ``None`` when not done."""
        return self._park_ok

    def corrected_yaw_rad(self, yaw_rad: float) -> float:
        """INS heading minus the applied correction, wrapped to [-pi, pi)."""
        return wrap_pi(yaw_rad - self.correction_rad)

    def estimate(self) -> HeadingEstimate:
        """The running estimate of the current accumulation (S4 recursions)."""
        s = self._stats
        eps = self._z * math.sqrt(s.var / (s.n - 1)) if s.n >= 2 else math.inf
        return HeadingEstimate(wrap_pi(s.mean), math.sqrt(s.var), eps, s.n, self._n_legs)

    def mismatches_rad(self) -> np.ndarray:
        """Mismatches of the current accumulation (unwrapped about the mean), rad, shape (n,)."""
        return np.asarray(self._x, dtype=np.float64)

    def cycle_times_s(self) -> np.ndarray:
        """Times of validity of the cycles of the current accumulation, s, shape (n,)."""
        return np.asarray(self._t, dtype=np.float64)

    def running_mean_spread_rad(self) -> float:
        """Spread (1 sigma) of the running mean since ``spread_start_cycle``, rad."""
        return math.sqrt(self._mean_stats.var) if self._mean_stats.n >= 2 else 0.0

    # ------------------------------------------------------------------ ground

    def on_ground(self, fix: GnssFix, speed_mps: float) -> bool:
        """On the ground? The autopilot's landed state when sent, else inferred.

        Fallback inference (no EXTENDED_SYS_STATE): on the ground while the
        ground speed is at most ``max_speed_mps`` (no take-off run), the height
        above the ground reference (the mean altitude of the parked fixes, or the
        first fix) is at most ``ground_max_height_m`` and, when VFR_HUD is sent,
        the climb rate is at most ``ground_max_climb_mps`` in magnitude.
        """
        if self._on_ground_explicit is not None:
            return self._on_ground_explicit
        alt = fix.alt_msl_m
        if not math.isfinite(alt):
            return False
        if self._ground_ref_alt_m is None:
            self._ground_ref_alt_m = alt
        if speed_mps > self.config.max_speed_mps:
            return False
        if abs(alt - self._ground_ref_alt_m) > self.config.ground_max_height_m:
            return False
        return not (
            self._climb_mps is not None and abs(self._climb_mps) > self.config.ground_max_climb_mps
        )

    # ------------------------------------------------------------------ internals

    def _reject(self, reason: str) -> None:
        self.rejections[reason] += 1
        n = self.rejections[reason]
        if n & (n - 1) == 0:  # log the 1st, 2nd, 4th, 8th ... occurrence
            logger.debug("heading cycle not used: %s (x%d)", reason, n)

    def _clear_attitude(self) -> None:
        self._att_t.clear()
        self._att_yaw.clear()
        self._att_turning.clear()
        self._att_rate.clear()

    def _fix_velocity(self, fix: GnssFix) -> tuple[float, float] | None:
        if fix.fix_type < self.config.min_fix_type:
            self._reject("fix_type")
            return None
        if fix.vel_ne_mps is None:
            self._reject("no_velocity")
            return None
        vel = np.asarray(fix.vel_ne_mps, dtype=np.float64)
        if vel.shape != (2,) or not np.all(np.isfinite(vel)):
            self._reject("velocity_invalid")
            return None
        if fix.vel_acc_mps is not None and not (
            math.isfinite(fix.vel_acc_mps) and fix.vel_acc_mps <= self.config.max_vel_acc_mps
        ):
            self._reject("vel_acc")
            return None
        return float(vel[0]), float(vel[1])

    def _vel_sigma(self, fix: GnssFix) -> float:
        if fix.vel_acc_mps is None:
            return self.config.default_vel_acc_mps
        return max(fix.vel_acc_mps, self.config.vel_acc_floor_mps)

    def _yaw_at(self, t_s: float) -> tuple[float, bool] | None:
        """INS heading interpolated at ``t_s`` and whether the last settle_time_s was straight."""
        ts = self._att_t
        if not ts:
            self._reject("no_attitude")
            return None
        k = bisect.bisect_right(ts, t_s)  # ts[k-1] <= t_s < ts[k]
        if k == 0:
            self._reject("attitude_too_new")
            return None
        if k == len(ts):
            dt = t_s - ts[-1]
            if dt > self.config.max_extrapolation_s:
                self._reject("attitude_too_old")
                return None
            yaw = wrap_pi(self._att_yaw[-1] + self._att_rate[-1] * dt)
        else:
            t0, t1 = ts[k - 1], ts[k]
            if t1 - t0 > self.config.max_attitude_gap_s:
                self._reject("attitude_gap")
                return None
            frac = (t_s - t0) / (t1 - t0)
            y0 = self._att_yaw[k - 1]
            yaw = wrap_pi(y0 + frac * wrap_pi(self._att_yaw[k] - y0))
        # straight: no turning sample in [t_s - settle, t_s] (and the bracketing one),
        # and the history reaches back that far
        start = t_s - self.config.settle_time_s
        if ts[0] > start:
            return yaw, False
        j = max(bisect.bisect_left(ts, start) - 1, 0)
        k_end = min(k + 1, len(ts))
        straight = not any(self._att_turning[j:k_end])
        return yaw, straight

    def _cycle(self, fix: GnssFix, vn: float, ve: float, speed: float) -> None:
        cfg = self.config
        if speed < cfg.min_speed_mps:
            self._end_leg()
            self._reject("slow")
            return
        got = self._yaw_at(fix.t_s)
        if got is None:
            self._end_leg()
            return
        yaw, straight = got
        if not straight:
            self._end_leg()
            self._reject("turn")
            return
        if len(self._x) >= cfg.max_cycles:
            self._reject("max_cycles")
            return
        if self._source_for(fix) == "position":
            got_pos = self._position_track(fix)
            if got_pos is None:
                return
            track, sig_track2, t_mid = got_pos
            got_mid = self._yaw_at(t_mid)
            if got_mid is None:
                return
            yaw = got_mid[0]
            t_cycle = t_mid
        else:
            track = math.atan2(ve, vn)
            sig_track2 = (self._vel_sigma(fix) / speed) ** 2
            t_cycle = fix.t_s
        if not self._in_leg:
            self._leg_id += 1
            self._n_legs += 1
            self._leg_cycles = 0
            self._in_leg = True
        self._leg_cycles += 1
        if self._leg_cycles == cfg.min_leg_cycles:
            self._full_legs += 1
        dphi = wrap_pi(yaw - track - self._crab_rad)
        # unwrap about the running mean so that a mismatch near +-180 deg stays continuous
        x = dphi if self._stats.n == 0 else self._stats.mean + wrap_pi(dphi - self._stats.mean)
        self._stats = self._stats.update(x)
        if self._stats.n >= self._spread_start():
            self._mean_stats = self._mean_stats.update(self._stats.mean)
        self._t.append(t_cycle)
        self._x.append(x)
        self._sig.append(math.sqrt(sig_track2 + self._ins_var_rad2))
        self._leg.append(self._leg_id)

    def _position_track(self, fix: GnssFix) -> tuple[float, float, float] | None:
        """Track angle (rad), its variance (rad^2) and mid time (s) from the displacement.

        The displacement since the fix ``pos_baseline_s`` earlier on the same straight
        leg, north and east on the ellipsoid (meridian and prime-vertical radii).
        """
        cfg = self.config
        here = (fix.t_s, fix.lat_rad, fix.lon_rad, int(fix.fix_type))
        prev = self._pos_prev
        if fix.fix_type < cfg.pos_min_fix_type or not (
            math.isfinite(fix.lat_rad) and math.isfinite(fix.lon_rad)
        ):
            self._pos_prev = None
            self._reject("position_fix_type")
            return None
        if prev is None or prev[3] != here[3] or fix.t_s - prev[0] > 2.0 * cfg.pos_baseline_s:
            self._pos_prev = here
            return None
        dt = fix.t_s - prev[0]
        if dt < cfg.pos_baseline_s - 1e-6:
            return None
        self._pos_prev = here
        m_m, n_m = radii_of_curvature_m(0.5 * (fix.lat_rad + prev[1]))
        d_n = (fix.lat_rad - prev[1]) * m_m
        d_e = wrap_pi(fix.lon_rad - prev[2]) * n_m * math.cos(fix.lat_rad)
        dist = math.hypot(d_n, d_e)
        if dist < cfg.min_speed_mps * dt:
            self._reject("slow")
            return None
        var = 2.0 * cfg.pos_diff_sigma_m**2 / dist**2
        return math.atan2(d_e, d_n), var, 0.5 * (fix.t_s + prev[0])

    def _source_for(self, fix: GnssFix) -> str:
        """The track source of this sample (fixed at its first cycle in ``auto``)."""
        cfg = self.config
        if cfg.track_source != "auto":
            return cfg.track_source
        want = "position" if fix.fix_type >= cfg.pos_min_fix_type else "velocity"
        if self._source is None:
            self._source = want
        elif self._source == "position" and want == "velocity":
            # RTK lost mid-sample: start over on the Doppler track rather than mix
            self._reject("track_source_changed")
            self._restart()
            self._source = want
        return self._source

    def _min_cycles(self) -> int:
        pos = self._source == "position" or self.config.track_source == "position"
        return self.config.pos_min_cycles if pos else self.config.min_cycles

    def _spread_start(self) -> int:
        pos = self._source == "position" or self.config.track_source == "position"
        return self.config.pos_spread_start_cycle if pos else self.config.spread_start_cycle

    def _end_leg(self) -> None:
        self._in_leg = False
        self._pos_prev = None

    def _restart(self) -> None:
        self.phase = HeadingPhase.ACCUMULATING
        self._stats = RunningStats()
        self._mean_stats = RunningStats()
        self._t.clear()
        self._x.clear()
        self._sig.clear()
        self._leg.clear()
        self._n_legs = 0
        self._full_legs = 0
        self._in_leg = False
        self._pos_prev = None
        self._candidate = None
        self._source = None

    # park check -------------------------------------------------------------

    def _park_reset(self) -> None:
        self._park_recent.clear()
        self._park_start_t = None
        self._park_vel.clear()
        self._park_last_eval_t = None

    def _park_step(self, fix: GnssFix, vn: float, ve: float, speed: float) -> list[Output]:
        cfg = self.config
        # parked: the mean GNSS velocity over the last park_smooth_s is at most park_speed_mps
        # (one noisy fix must not end the parking; a taxiing speed ends it at once)
        self._park_recent.append((fix.t_s, vn, ve))
        while self._park_recent and self._park_recent[0][0] < fix.t_s - cfg.park_smooth_s:
            self._park_recent.pop(0)
        m_n = sum(v[1] for v in self._park_recent) / len(self._park_recent)
        m_e = sum(v[2] for v in self._park_recent) / len(self._park_recent)
        if speed >= cfg.min_speed_mps or math.hypot(m_n, m_e) > cfg.park_speed_mps:
            self._park_reset()
            return []
        if self._park_start_t is None:
            self._park_start_t = fix.t_s
        self._park_vel.append((fix.t_s, vn, ve))
        # ground reference altitude: the mean of parked fixes
        if math.isfinite(fix.alt_msl_m):
            self._ground_ref_n += 1
            ref = self._ground_ref_alt_m if self._ground_ref_alt_m is not None else fix.alt_msl_m
            self._ground_ref_alt_m = ref + (fix.alt_msl_m - ref) / self._ground_ref_n
        horizon = fix.t_s - cfg.park_window_s
        while self._park_vel and self._park_vel[0][0] < horizon:
            self._park_vel.pop(0)
        if fix.t_s - self._park_start_t < cfg.park_time_s:
            return []
        if (
            self._park_last_eval_t is not None
            and fix.t_s - self._park_last_eval_t < cfg.park_time_s
        ):
            return []
        self._park_last_eval_t = fix.t_s
        verdict = self.park_verdict(np.array([[v[1], v[2]] for v in self._park_vel]))
        self._park_ok = verdict.ok
        if verdict.ok:
            self._park_reject_sent = False
            logger.info("parked GNSS velocity check passed: %s", verdict.details)
            return []
        logger.warning("parked GNSS velocity check failed: %s", verdict.details)
        if self._park_reject_sent:
            return []
        self._park_reject_sent = True
        self.reject_alerts += 1
        return [Alert(fix.t_s, AlertCode.HDG_REJECT, Severity.WARNING, verdict.reason)]

    def park_verdict(self, vel_ne_mps: np.ndarray) -> Verdict:
        """Parked check: is the mean GNSS velocity (shape (n, 2)) a bias?

        A bias is declared when the mean velocity is both significant (Hotelling
        T^2 against zero, approximated by chi-square with 2 degrees of freedom at
        ``park_alpha``) and larger than ``park_max_bias_mps``.

        References
        ----------
        S4, parking-stand check (GNSS speed <= 0.2 m/s for 10-30 s).
        """
        n = vel_ne_mps.shape[0]
        if n < 3:
            return Verdict(False, "park_too_few", {"n": float(n)})
        mean = vel_ne_mps.mean(axis=0)
        cov = np.cov(vel_ne_mps, rowvar=False) / n
        cov += np.eye(2) * 1e-12
        t2 = float(mean @ np.linalg.solve(cov, mean))
        limit = float(stats.chi2.ppf(1.0 - self.config.park_alpha, 2))
        bias = float(np.hypot(mean[0], mean[1]))
        details = {"bias_mps": bias, "t2": t2, "t2_limit": limit, "n": float(n)}
        if t2 > limit and bias > self.config.park_max_bias_mps:
            return Verdict(False, f"gnss_vel_bias {bias:.3f}m/s", details)
        return Verdict(True, "", details)

    # criteria ---------------------------------------------------------------

    def _maybe_judge(self, t_s: float) -> list[Output]:
        cfg = self.config
        est = self.estimate()
        if est.n < self._min_cycles() or self._full_legs < cfg.min_legs:
            return []
        if math.degrees(est.eps_rad) > cfg.eps_limit_deg and est.n < cfg.max_cycles:
            return []
        verdict = self.judge()
        if not verdict.ok:
            logger.warning("heading correction rejected: %s %s", verdict.reason, verdict.details)
            self._restart()
            self.reject_alerts += 1
            return [Alert(t_s, AlertCode.HDG_REJECT, Severity.WARNING, verdict.reason)]
        self._candidate = est
        self.phase = HeadingPhase.READY
        text = self._format(est)
        logger.info("heading correction ready: %s (%s)", text, verdict.details)
        out: list[Output] = [Alert(t_s, AlertCode.HDG_READY, Severity.NOTICE, text)]
        if cfg.auto_apply:
            out.extend(self.apply(t_s))
        return out

    def judge(self) -> Verdict:
        """Evaluate the S4 acceptance criteria on the current accumulation.

        Order (the first failure is the reason): sufficiency, park check,
        running-mean spread, dispersion, normality, trend, leg consistency.

        References
        ----------
        S4, acceptance criteria; the trend and leg tests are additions aimed at
        a changing crab angle and a biased GNSS velocity.
        """
        cfg = self.config
        est = self.estimate()
        x = np.asarray(self._x, dtype=np.float64)
        sig = np.asarray(self._sig, dtype=np.float64)
        t = np.asarray(self._t, dtype=np.float64)
        leg = np.asarray(self._leg, dtype=np.int64)
        n = x.size
        d: dict[str, float] = {"n": float(n), "eps_deg": math.degrees(est.eps_rad)}
        if n < self._min_cycles() or math.degrees(est.eps_rad) > cfg.eps_limit_deg:
            return Verdict(False, f"insufficient eps={math.degrees(est.eps_rad):.3f}", d)
        if cfg.require_park_check and self._park_ok is not True:
            reason = "no_park_check" if self._park_ok is None else "gnss_vel_bias"
            return Verdict(False, reason, d)
        # spread of the running mean (S4: sigma[mean] <= 0.3 deg)
        spread_deg = math.degrees(self.running_mean_spread_rad())
        d["spread_deg"] = spread_deg
        if spread_deg > cfg.mean_spread_limit_deg:
            return Verdict(False, f"mean_spread {spread_deg:.2f}>{cfg.mean_spread_limit_deg}", d)
        # dispersion: observed scatter vs GNSS track + INS course variances (chi-square)
        resid = x - self._stats.mean
        t_disp = float(np.sum((resid / sig) ** 2))
        disp_limit = float(stats.chi2.ppf(1.0 - cfg.dispersion_alpha, n - 1))
        d["dispersion_ratio"] = t_disp / (n - 1)
        d["dispersion_limit_ratio"] = disp_limit / (n - 1)
        if t_disp > disp_limit:
            return Verdict(False, f"dispersion {t_disp / (n - 1):.2f}x", d)
        # normality of the standardised mismatch
        z = resid / sig
        p_norm = float(stats.normaltest(z).pvalue)
        d["normality_p"] = p_norm
        if p_norm < cfg.normality_alpha:
            return Verdict(False, f"not_normal p={p_norm:.1e}", d)
        # trend of the mismatch in time (weighted least squares, t test)
        w = 1.0 / sig**2
        tc = t - np.sum(w * t) / np.sum(w)
        stt = float(np.sum(w * tc * tc))
        if stt > 0.0:
            slope = float(np.sum(w * tc * resid) / stt)
            rss = float(np.sum(w * (resid - slope * tc) ** 2))
            se = math.sqrt(rss / (n - 2) / stt)
            t_stat = abs(slope) / se if se > 0 else math.inf
            drift_deg = abs(math.degrees(slope) * float(t[-1] - t[0]))
            t_limit = float(stats.t.ppf(1.0 - cfg.stationarity_alpha / 2.0, n - 2))
            d["drift_deg"] = drift_deg
            d["trend_t"] = t_stat
            if t_stat > t_limit and drift_deg > cfg.max_drift_deg:
                return Verdict(False, f"trend {drift_deg:.2f}deg", d)
        # leg consistency (weighted one-way analysis of variance, F test)
        legs = [k for k in np.unique(leg) if np.count_nonzero(leg == k) >= cfg.min_leg_cycles]
        if len(legs) >= 2:
            sel = np.isin(leg, legs)
            xs, ws, ls = x[sel], w[sel], leg[sel]
            m_all = float(np.sum(ws * xs) / np.sum(ws))
            between = 0.0
            within = 0.0
            means = []
            for k in legs:
                mk = ls == k
                wk = ws[mk]
                m_k = float(np.sum(wk * xs[mk]) / np.sum(wk))
                means.append(m_k)
                between += float(np.sum(wk)) * (m_k - m_all) ** 2
                within += float(np.sum(wk * (xs[mk] - m_k) ** 2))
            k_legs = len(legs)
            n_sel = xs.size
            f_stat = (between / (k_legs - 1)) / (within / (n_sel - k_legs))
            f_limit = float(stats.f.ppf(1.0 - cfg.stationarity_alpha, k_legs - 1, n_sel - k_legs))
            leg_range_deg = math.degrees(max(means) - min(means))
            d["leg_f"] = f_stat
            d["leg_range_deg"] = leg_range_deg
            if f_stat > f_limit and leg_range_deg > cfg.max_drift_deg:
                return Verdict(False, f"legs_differ {leg_range_deg:.2f}deg", d)
        return Verdict(True, "", d)

    # publication -------------------------------------------------------------

    def _format(self, est: HeadingEstimate) -> str:
        return f"{math.degrees(est.correction_rad):.2f} ±{math.degrees(est.eps_rad):.2f} n={est.n}"

    def _publish(self, t_s: float, on_ground: bool) -> list[Output]:
        if self.phase is HeadingPhase.APPLIED:
            est = self._applied
        elif self.phase is HeadingPhase.READY:
            est = self._candidate
        else:
            est = self.estimate()
        if est is None or est.n < 2 or (self.phase is HeadingPhase.ACCUMULATING and not on_ground):
            return []
        if (
            self._last_publish_t is not None
            and t_s - self._last_publish_t < self.config.publish_period_s
            and t_s >= self._last_publish_t
        ):
            return []
        self._last_publish_t = t_s
        return [
            NamedValue(t_s, "CMP_HDGC", math.degrees(est.correction_rad)),
            NamedValue(t_s, "CMP_HDGE", math.degrees(est.eps_rad)),
        ]

    # persistence -------------------------------------------------------------

    def to_state(self) -> dict[str, Any]:
        """Plain, JSON-compatible dictionary of everything that must survive a restart.

        The attitude buffer (a few seconds) is not kept: after a restart the
        first cycles wait for ``settle_time_s`` of attitude.
        """

        def est(e: HeadingEstimate | None) -> dict[str, Any] | None:
            return None if e is None else asdict(e)

        return {
            "version": STATE_VERSION,
            "phase": self.phase.value,
            "stats": asdict(self._stats),
            "mean_stats": asdict(self._mean_stats),
            "t_s": list(self._t),
            "x_rad": list(self._x),
            "sigma_rad": list(self._sig),
            "leg": list(self._leg),
            "leg_id": self._leg_id,
            "park_ok": self._park_ok,
            "park_reject_sent": self._park_reject_sent,
            "ground_ref_alt_m": self._ground_ref_alt_m,
            "ground_ref_n": self._ground_ref_n,
            "candidate": est(self._candidate),
            "applied": est(self._applied),
            "last_publish_t_s": self._last_publish_t,
            "rejections": dict(self.rejections),
            "reject_alerts": self.reject_alerts,
            "source": self._source,
        }

    @classmethod
    def from_state(cls, config: HeadingConfig, state: dict[str, Any]) -> HeadingCorrector:
        """Rebuild a corrector from :meth:`to_state` output (ValueError when malformed)."""
        if not isinstance(state, dict):
            raise ValueError("heading state must be a dict")
        if state.get("version") != STATE_VERSION:
            raise ValueError(f"heading state version {state.get('version')!r} != {STATE_VERSION}")
        try:
            obj = cls(config)
            obj.phase = HeadingPhase(state["phase"])
            obj._stats = _stats_from(state["stats"])
            obj._mean_stats = _stats_from(state["mean_stats"])
            obj._t = [float(v) for v in state["t_s"]]
            obj._x = [float(v) for v in state["x_rad"]]
            obj._sig = [float(v) for v in state["sigma_rad"]]
            obj._leg = [int(v) for v in state["leg"]]
            obj._leg_id = int(state["leg_id"])
            obj._n_legs = len(set(obj._leg))
            counts = Counter(obj._leg)
            obj._full_legs = sum(1 for c in counts.values() if c >= config.min_leg_cycles)
            obj._leg_cycles = counts[obj._leg[-1]] if obj._leg else 0
            park_ok = state["park_ok"]
            obj._park_ok = None if park_ok is None else bool(park_ok)
            obj._park_reject_sent = bool(state["park_reject_sent"])
            ref = state["ground_ref_alt_m"]
            obj._ground_ref_alt_m = None if ref is None else float(ref)
            obj._ground_ref_n = int(state["ground_ref_n"])
            obj._candidate = _estimate_from(state["candidate"])
            obj._applied = _estimate_from(state["applied"])
            last = state["last_publish_t_s"]
            obj._last_publish_t = None if last is None else float(last)
            obj.rejections = Counter({str(k): int(v) for k, v in state["rejections"].items()})
            obj.reject_alerts = int(state["reject_alerts"])
            source = state.get("source")
            if source is not None and source not in TRACK_SOURCES:
                raise ValueError(f"heading state malformed: source {source!r}")
            obj._source = source
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"heading state malformed: {exc!r}") from exc
        lengths = {len(obj._t), len(obj._x), len(obj._sig), len(obj._leg)}
        if len(lengths) != 1 or obj._stats.n != len(obj._x):
            raise ValueError("heading state malformed: cycle arrays disagree")
        if obj.phase is HeadingPhase.APPLIED and obj._applied is None:
            raise ValueError("heading state malformed: APPLIED without an applied estimate")
        if obj.phase is HeadingPhase.READY and obj._candidate is None:
            raise ValueError("heading state malformed: READY without a candidate")
        return obj


def _stats_from(d: dict[str, Any]) -> RunningStats:
    return RunningStats(int(d["n"]), float(d["mean"]), float(d["var"]))


def _estimate_from(d: dict[str, Any] | None) -> HeadingEstimate | None:
    if d is None:
        return None
    return HeadingEstimate(
        float(d["correction_rad"]),
        float(d["sigma_rad"]),
        float(d["eps_rad"]),
        int(d["n"]),
        int(d["legs"]),
    )
