"""The spoofing monitor's settings: the ``[spoof]`` block.

The IMU's figures come from the grade table (:data:`companion.nav.grades.IMU_GRADES`,
``ATTITUDE_ERROR_BY_GRADE``) through :meth:`SpoofConfig.for_grade`, as the blend's and
the coasting references' do; the receiver's velocity noise and the IMU's vibration are
measured in flight, never taken from what the receiver claims.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.nav.grades import ATTITUDE_ERROR_BY_GRADE, IMU_GRADES
from companion.ranges import check_ranges, ranged

_G = 9.80665
WINDOW_EDGES_S = (2.0, 5.0, 10.0, 20.0, 40.0)
"""Window classes of the in-flight calibration: tau below 2 s, 2-5 s, ... , above 40 s."""


@dataclass(frozen=True, slots=True)
class SpoofConfig:
    """Settings of the spoofing monitor (validated): the drag test (:mod:`.drag`) and the
    episodes (:mod:`.monitor`). :meth:`for_grade` fills the IMU grade's figures."""

    enabled: bool = True
    """Test every receiver's motion against the IMU's (a spoofer that tracks the vehicle);
    off: no SPOOF from the IMU (the receivers' own spoofing flags still count)."""

    false_alarm_prob: float = ranged(1e-9, gt=0.0, lt=1.0)
    """Per-fix probability that the largest of the tests fails with an honest receiver
    (shared among the window classes)."""
    anchor_interval_s: float = ranged(1.0, gt=0.0)
    """A new reference every this long while nothing is suspected, s."""
    max_window_s: float = ranged(120.0, gt=0.0)
    """The oldest reference kept, s: a drag is seen against references anchored before it
    for this long."""
    settle_s: float = ranged(20.0, ge=0.0)
    """References are kept only after the filter has run this long (its biases settled)."""
    calm_s: float = ranged(5.0, ge=0.0)
    """... nor within this long of a fix that pulled the filter (an innovation beyond its
    1e-3 quantile: its biases may be learning a disturbance), s."""
    calibration_tau_s: float = ranged(300.0, gt=0.0)
    """Memory of the in-flight calibration of the test statistic, s."""
    calibration_prior: float = ranged(4.0, ge=1.0)
    """The calibration's factor before any evidence (the real autopilots of
    ../shared/realdata need 2-25 over their flights): the test starts wide ..."""
    calibration_prior_fixes: float = ranged(150.0, gt=0.0)
    """... and the prior weighs as much as this many tested fixes."""
    max_calibration: float = ranged(100.0, ge=1.0)
    """The calibration scales the separation variance by at most this."""
    gnss_vel_floor_mps: float = ranged(0.02, gt=0.0)
    """The receiver's white velocity noise is at least this, m/s (1-sigma)."""
    gnss_vel_slow_mps: float = ranged(0.05, ge=0.0)
    """The slowly wandering part of a receiver's velocity error, m/s (1-sigma; a u-blox
    M8/F9 specifies 0.05 m/s)."""
    gnss_vel_slow_tau_s: float = ranged(20.0, gt=0.0)
    """... and its correlation time, s."""
    acc_bias_sigma_mps2: float = ranged(0.5, gt=0.0)
    """Prior 1-sigma of the body-frame accelerometer bias across the body's x and y axes,
    m/s^2 (generous: a real autopilot's attitude and accelerometer disagree by 1-5 deg of
    tilt, which reads as a bias across gravity) ..."""
    acc_bias_z_sigma_mps2: float = ranged(10e-3 * _G, gt=0.0)
    """... and along its z axis, m/s^2 (the grade's turn-on bias: a tilt hardly changes
    what the z axis reads)."""
    tilt_bias_sigma_mps2: float = ranged(_G * math.radians(0.3), gt=0.0)
    """Prior 1-sigma of the NED bias (the attitude's tilt error times g), m/s^2: an
    autopilot's attitude estimate is good to a few tenths of a degree in flight. The
    1-5 deg by which the ArduPilot logs of ../shared/realdata disagree with their
    accelerometers is a body-frame error (a body-frame bias explains it down to 0.10-0.24
    m/s^2 over 10 s windows, a NED one only to 0.22-0.35; NED and body together hardly
    better than body alone), so that one is the body-frame bias's."""
    acc_bias_rw_m2ps5: float = ranged(2.0 * (0.2e-3 * _G) ** 2 / 100.0, ge=0.0)
    """Random-walk PSD of the body-frame bias, (m/s^2)^2/s (grade: 2 sigma^2 / tau of its
    instability)."""
    tilt_rw_m2ps5: float = ranged(2.0 * (_G * math.radians(0.05)) ** 2 / 60.0, ge=0.0)
    """Random-walk PSD of the NED bias, (m/s^2)^2/s (grade: 2 (g sigma_tilt)^2 / tau of
    the autopilot's attitude error)."""
    wander_prior_m2ps5: float = ranged(1e-3, ge=0.0)
    """The apparent bias's random walk before it is measured in flight, (m/s^2)^2/s: what
    the attitude of the ArduPilot copters of ../shared/realdata wanders by (about 1 deg a
    minute); a better autopilot shows less within minutes, and the test sharpens."""
    wander_tau_s: float = ranged(60.0, gt=0.0)
    """Memory of the wander's measurement, s: it follows the vehicle within minutes."""
    lag_sigma_s: float = ranged(0.2, ge=0.0)
    """1-sigma of what is not known of the fixes' time of validity against the IMU's (a
    GNSS lag not yet measured: receivers and autopilots differ by 0.1-0.25 s), s: a
    misplaced fix moves the velocity by the acceleration times it. Once the service has
    measured receiver 0's lag (:mod:`companion.engine.gnss_lag`) the measurement's own
    uncertainty (its difference from the lag in use, or its sigma) replaces it ..."""
    lag_sigma_floor_s: float = ranged(0.02, ge=0.0)
    """... at least this, s."""
    attitude_time_sigma_s: float = ranged(0.05, ge=0.0)
    """1-sigma of the attitude's time against the IMU's, s (a stream's own lag, a stamp
    offset): in a turn the specific force is rotated by omega times it, which the test
    allows for through the IMU's ``int |omega x f| dt`` since the anchor."""
    accel_smoothing_s: float = ranged(0.5, gt=0.0)
    """The acceleration for that term is the mean over this long before the fix, s."""
    acc_vrw_floor_m2ps3: float = ranged((150e-6 * _G) ** 2, ge=0.0)
    """The specific force's white noise PSD is at least this, m^2/s^3 (the grade's)."""

    persist_fixes: int = ranged(3, ge=1)
    """A receiver is found spoofed after this many consecutive failed fixes ..."""
    persist_s: float = ranged(1.0, ge=0.0)
    """... spanning at least this long, s (one bad fix is a glitch, not a spoofer)."""
    readmit_s: float = ranged(5.0, ge=0.0)
    """A held-out receiver is re-admitted once it has agreed with the episode's reference
    this long, s ..."""
    readmit_false_alarm_prob: float = ranged(1e-2, gt=0.0, lt=1.0)
    """... within the chi-square (2 dof) quantile of this probability: an agreement, not
    the mere absence of a detection."""
    verified_accel_mps2: float = ranged(0.5, gt=0.0)
    """GNSS_INTEGRITY says spoofing "clean" only while every tested receiver's drag test
    sees a drag this strong ...  (a consistent spoofer's fast drag, Tanil et al.) ..."""
    verified_window_s: float = ranged(10.0, gt=0.0)
    """... within this long, s; else "unknown": the IMU stream cannot tell (published as
    ``CMP_SPF_A``, the smallest drag seen within that window, m/s^2)."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if not isinstance(self.persist_fixes, int):
            raise ValueError(f"persist_fixes must be an integer, got {self.persist_fixes!r}")

    @classmethod
    def for_grade(cls, grade: str, **overrides: object) -> SpoofConfig:
        """The figures of an IMU grade (``"tactical"``, ``"mems"``) from the grade table."""
        if grade not in IMU_GRADES or grade not in ATTITUDE_ERROR_BY_GRADE:
            raise ValueError(f"unknown IMU grade {grade!r}")
        g = IMU_GRADES[grade]
        att, att_tau = ATTITUDE_ERROR_BY_GRADE[grade]
        tilt = _G * max(att[0], att[1])
        params: dict[str, object] = {  # GRADE_FIELDS
            "acc_bias_rw_m2ps5": 2.0 * g.acc_instability_mps2**2 / g.acc_tau_s,
            "tilt_rw_m2ps5": 2.0 * tilt**2 / att_tau,
            "acc_vrw_floor_m2ps3": g.acc_noise_density_mps2_rthz**2,
            "acc_bias_z_sigma_mps2": math.hypot(g.acc_bias_sigma_mps2, g.acc_instability_mps2),
        }
        params.update(overrides)
        return cls(**params)  # type: ignore[arg-type]


GRADE_FIELDS = (
    "acc_bias_rw_m2ps5",
    "tilt_rw_m2ps5",
    "acc_vrw_floor_m2ps3",
    "acc_bias_z_sigma_mps2",
)
"""The figures :meth:`SpoofConfig.for_grade` takes from an IMU grade."""
