"""Configuration of the taxi heading correction (the ``[heading]`` block).

Each field's range is declared beside it with :func:`companion.ranges.ranged`;
``__post_init__`` adds the fix-type conversion and the checks that relate fields.
"""

from __future__ import annotations

from dataclasses import dataclass

from scipy import stats

from companion.ranges import check_ranges, ranged
from companion.types import FixType

TRACK_SOURCES = ("auto", "velocity", "position")
"""Allowed :attr:`HeadingConfig.track_source` values."""


@dataclass(frozen=True, slots=True)
class HeadingConfig:
    """Settings of the taxi heading correction (Markelov et al.).

    Markelov et al., "INS course correction from satellite navigation before
    take-off"; the method is summarised in :mod:`companion.nav.heading` and
    ``docs/methods.md``.

    Attributes
    ----------
    min_speed_mps
        Lowest GNSS ground speed of a counted cycle, m/s. Markelov et al. used
        6 m/s. The default 2.5 m/s (about 5 kt) is reached by every straight
        taxi (light aircraft and UAVs taxi at 5-15 kt, airliners at 15-20 kt)
        and stays above apron manoeuvring and pushback, where nose-wheel
        steering makes track and heading differ. The track-angle noise grows as
        ``vel_acc / speed``; the accuracy ``eps`` accounts for it.
    max_speed_mps
        Highest ground speed of a counted cycle, m/s: above it the vehicle is
        on its take-off or landing run, not taxiing.
    max_turn_rate_dps
        INS heading rate above which the vehicle is turning, deg/s
        (Markelov et al.: 1).
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
        dispersion of the dispersion criterion of Markelov et al.).
    track_source
        Where the GNSS track angle of a cycle comes from. ``"velocity"``
        (Markelov et al.): ``atan2(V_E, V_N)`` of each fix's velocity.
        ``"position"`` (an extension): the direction of the displacement
        between two fixes ``pos_baseline_s`` apart on the same straight leg,
        one cycle per baseline (non-overlapping, so that cycles stay
        independent). With RTK positions (millimetre-to-centimetre noise
        between epochs) it is one to two orders of magnitude less noisy than
        the Doppler velocity at taxi speeds; with a 3D fix it is worse. The
        recursions and criteria are the same. ``"auto"`` (the default): the
        position track while the fixes are at least ``pos_min_fix_type``, the
        velocity track otherwise; the source is chosen at the first cycle of a
        sample, and a position-track sample that loses RTK starts over on the
        velocity track (never a mix).
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
        Sufficiency limit of the 95 % accuracy ``eps`` of the mean, deg
        (Markelov et al.: 0.05).
    confidence
        Two-sided confidence of ``eps`` (Markelov et al.: 0.95, i.e. 1.96 sigma).
    min_cycles
        Fewest velocity-track cycles before the sample is judged (the tests need
        a sample).
    pos_min_cycles
        The same for position-track cycles (one per ``pos_baseline_s``).
    max_cycles
        Cap on stored cycles (memory bound); beyond it the sample is judged as is.
    mean_spread_limit_deg
        Limit on the spread (1 sigma) of the running mean, deg (Markelov et al.: 0.3).
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
        Markelov et al. need one. A GNSS velocity bias (or a crab angle) on a
        single heading is indistinguishable from a heading error; it shows as a
        difference between legs of different headings, so 2 makes the leg test
        mandatory (the parked check is the other guard).
    require_park_check
        Refuse READY unless a parked check passed (Markelov et al. do it first).
    park_speed_mps
        GNSS speed at or below which the vehicle is parked, m/s (Markelov et al.: 0.2).
    park_time_s
        Parked time after which the GNSS velocity bias is checked, s
        (Markelov et al.: 10-30).
    park_window_s
        Longest parked window used by the check (most recent), s.
    park_smooth_s
        The parked speed is that of the mean GNSS velocity over this time, s
        (a single noisy fix must not end the parking).
    park_max_bias_mps
        Largest tolerated GNSS velocity bias while parked, m/s. Real receivers report
        0.1-0.2 m/s at standstill (multipath, correlated over tens of seconds) that is not
        there in motion; Markelov et al.'s parking stand allows 0.2 m/s of GNSS speed.
    park_suspect_bias_mps
        A significant parked bias above this (and at most ``park_max_bias_mps``) is not
        a rejection but a suspicion: the sample then needs ``suspect_min_legs`` legs, so
        that a bias that persists in motion shows between the legs' headings.
    suspect_min_legs
        Fewest legs judged after a suspect parked check (the leg test's second heading).
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
        Ground decision: largest height above the ground reference, m.
    ground_max_climb_mps
        Ground decision: largest climb rate magnitude (VFR_HUD), m/s.
    ground_max_pitch_deg
        Ground decision: largest pitch magnitude (ATTITUDE), deg (a tail-wheel
        aircraft sits at up to about 13 deg).
    ground_release_s
        After a flight the autopilot still calls "in air": how long the motion must
        show the ground (within ``ground_release_height_m`` of the reference) before
        the taxi is taken as resumed, s.
    ground_release_height_m
        Largest height above the ground reference for that release, m (tighter than
        ``ground_max_height_m``: a low hover is not a taxi).
    """

    min_speed_mps: float = ranged(2.5, gt=0.0)
    max_speed_mps: float = ranged(20.0, gt=0.0)
    max_turn_rate_dps: float = ranged(1.0, gt=0.0)
    settle_time_s: float = ranged(2.0, ge=0.0)
    receiver_id: int = 0
    min_fix_type: FixType = FixType.FIX_3D
    max_vel_acc_mps: float = ranged(0.5, gt=0.0)
    default_vel_acc_mps: float = ranged(0.1, gt=0.0)
    vel_acc_floor_mps: float = ranged(0.02, gt=0.0)
    ins_yaw_noise_deg: float = ranged(0.1, ge=0.0)
    track_source: str = ranged("auto", choices=TRACK_SOURCES)
    pos_baseline_s: float = ranged(1.0, gt=0.0)
    pos_diff_sigma_m: float = ranged(0.01, gt=0.0)
    pos_min_fix_type: FixType = FixType.RTK_FIXED
    ground_crab_deg: float = ranged(0.0, ge=-45.0, le=45.0)
    eps_limit_deg: float = ranged(0.05, gt=0.0)
    confidence: float = ranged(0.95, gt=0.0, lt=1.0)
    min_cycles: int = ranged(100, ge=20)
    pos_min_cycles: int = 30
    max_cycles: int = 50_000
    mean_spread_limit_deg: float = ranged(0.3, gt=0.0)
    spread_start_cycle: int = ranged(20, ge=2)
    pos_spread_start_cycle: int = ranged(10, ge=2)
    normality_alpha: float = ranged(0.001, gt=0.0, lt=0.5)
    dispersion_alpha: float = ranged(0.001, gt=0.0, lt=0.5)
    stationarity_alpha: float = ranged(0.001, gt=0.0, lt=0.5)
    max_drift_deg: float = ranged(0.5, gt=0.0)
    min_leg_cycles: int = ranged(20, ge=3)
    min_legs: int = ranged(1, ge=1)
    require_park_check: bool = True
    park_speed_mps: float = ranged(0.2, gt=0.0)
    park_time_s: float = ranged(10.0, gt=0.0)
    park_window_s: float = ranged(30.0, gt=0.0)
    park_smooth_s: float = ranged(2.0, gt=0.0)
    park_max_bias_mps: float = ranged(0.2, gt=0.0)
    park_suspect_bias_mps: float = ranged(0.05, gt=0.0)
    suspect_min_legs: int = ranged(3, ge=1)
    park_alpha: float = ranged(0.001, gt=0.0, lt=0.5)
    auto_apply: bool = False
    publish_period_s: float = ranged(1.0, ge=0.0)
    attitude_buffer_s: float = ranged(5.0, gt=0.0)
    max_attitude_gap_s: float = ranged(1.5, gt=0.0)
    max_extrapolation_s: float = ranged(0.2, ge=0.0)
    ground_max_height_m: float = ranged(15.0, gt=0.0)
    ground_max_climb_mps: float = ranged(1.5, gt=0.0)
    ground_max_pitch_deg: float = ranged(15.0, gt=0.0, le=90.0)
    ground_release_s: float = ranged(10.0, ge=0.0)
    ground_release_height_m: float = ranged(3.0, gt=0.0)

    def __post_init__(self) -> None:
        check_ranges(self)
        for name in ("min_fix_type", "pos_min_fix_type"):
            value = getattr(self, name)
            if not isinstance(value, FixType):
                try:  # a plain int from a config file
                    object.__setattr__(self, name, FixType(value))
                except (ValueError, TypeError) as exc:
                    raise ValueError(f"{name} must be a FixType, got {value!r}") from exc
        if self.max_speed_mps <= self.min_speed_mps:
            raise ValueError(
                f"max_speed_mps must be > min_speed_mps, "
                f"got {self.max_speed_mps!r} <= {self.min_speed_mps!r}"
            )
        if self.park_speed_mps >= self.min_speed_mps:
            raise ValueError(
                f"park_speed_mps must be < min_speed_mps, "
                f"got {self.park_speed_mps!r} >= {self.min_speed_mps!r}"
            )
        if self.park_window_s < self.park_time_s:
            raise ValueError(
                f"park_window_s must be >= park_time_s, "
                f"got {self.park_window_s!r} < {self.park_time_s!r}"
            )
        if self.max_cycles < self.min_cycles:
            raise ValueError(
                f"max_cycles must be >= min_cycles, got {self.max_cycles!r} < {self.min_cycles!r}"
            )
        if self.spread_start_cycle >= self.min_cycles:
            raise ValueError(
                f"spread_start_cycle must be < min_cycles, "
                f"got {self.spread_start_cycle!r} >= {self.min_cycles!r}"
            )
        if self.attitude_buffer_s < self.settle_time_s + self.max_attitude_gap_s:
            raise ValueError(
                "attitude_buffer_s must be >= settle_time_s + max_attitude_gap_s, "
                f"got {self.attitude_buffer_s!r}"
            )
        if self.pos_spread_start_cycle >= self.pos_min_cycles:
            raise ValueError(
                f"pos_spread_start_cycle must be < pos_min_cycles, "
                f"got {self.pos_spread_start_cycle!r} >= {self.pos_min_cycles!r}"
            )
        if self.pos_baseline_s > self.settle_time_s and self.track_source != "velocity":
            raise ValueError(
                "pos_baseline_s must be <= settle_time_s (the straight window must cover "
                f"the baseline), got {self.pos_baseline_s!r} > {self.settle_time_s!r}"
            )

    @property
    def z_score(self) -> float:
        """Two-sided normal quantile of ``confidence`` (1.96 for 95 %)."""
        return float(stats.norm.ppf(0.5 + 0.5 * self.confidence))
