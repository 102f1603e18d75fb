"""Configuration of the GNSS/INS blend: one frozen block, each field's range beside it.

Field notes that say "see the module docstring" refer to the package's overview,
:mod:`companion.nav.blend`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.nav.grades import IMU_GRADES
from companion.ranges import check_ranges, ranged

_DEG = math.pi / 180.0
_HOUR_S = 3600.0


@dataclass(frozen=True, slots=True)
class BlendConfig:
    """Configuration of :class:`BlendNavigator` (SI units; noise densities per sqrt(s))."""

    mode: str = ranged("attitude_aided", choices=("attitude_aided", "strapdown"))
    """``"attitude_aided"`` (autopilot ATTITUDE rotates the specific force) or ``"strapdown"``."""
    adaptive: bool = True
    """Adaptive R and Q (El-Mowafy 2005); False gives the non-adaptive baseline."""
    adaptive_window: int = ranged(25, ge=2, le=1000)
    """Moving-window length N in GNSS epochs (El-Mowafy 2005: 20-30)."""
    adaptive_min_epochs: int = ranged(10, ge=1)
    """Epochs in the window before the adaptive estimates are used."""
    lever_arm_b_m: tuple[float, float, float] = ranged((0.0, 0.0, 0.0), length=3)
    """GNSS antenna position relative to the IMU, body FRD axes, m."""
    accel_vrw_mps_rts: float = ranged(0.03 / 60.0, gt=0.0)
    """Accelerometer white noise (velocity random walk), m/s/sqrt(s)."""
    gyro_arw_rad_rts: float = ranged(0.05 * _DEG / 60.0, gt=0.0)
    """Gyro white noise (angle random walk), rad/sqrt(s)."""
    accel_bias_sigma_mps2: float = ranged(1e-3 * 9.80665, gt=0.0)
    """Accelerometer bias 1-sigma (Gauss-Markov steady state), m/s^2."""
    accel_bias_tau_s: float = ranged(3600.0, gt=0.0, finite=False)
    """Accelerometer bias correlation time, s (inf = random constant + walk)."""
    gyro_noise_measured: bool = True
    """Strapdown: when the gyro's measured white noise (second differences of its readings
    over windows of 500 samples) exceeds ``gyro_arw_rad_rts`` beyond chance, that measured
    density drives the attitude error instead: the vibration of a hand or an airframe,
    integrated by the INS as error, is noise a datasheet density does not hold
    (docs/methods.md, "Gyro noise measured in use")."""
    accel_noise_measured: bool = True
    """When the accelerometer's measured white noise (second differences of its readings
    over windows of 50 samples, capped by what its 0.1 s velocity steps show) exceeds
    ``accel_vrw_mps_rts`` beyond chance, that measured density is the accelerometer noise
    of the velocity error (the floor of the adaptive one): an airframe's vibration, aliased
    into the IMU stream, is integrated by the INS as velocity error a datasheet density
    does not hold (docs/methods.md, "Accelerometer noise measured in use")."""
    gyro_bias_sigma_radps: float = ranged(5.0 * _DEG / _HOUR_S, gt=0.0)
    """Gyro bias 1-sigma, rad/s."""
    gyro_bias_tau_s: float = ranged(3600.0, gt=0.0, finite=False)
    """Gyro bias correlation time, s."""
    gyro_instability_radps: float = ranged(10.0 * _DEG / _HOUR_S, gt=0.0)
    """Gyro bias instability 1-sigma, rad/s: the uncertainty of the autopilot's own gyro
    bias estimate when its body rates carry the attitude through a gap
    (:meth:`~companion.nav.blend.BlendNavigator.hold_attitude`)."""
    held_rates_lag_s: float = ranged(0.03, ge=0.0, le=1.0)
    """When the autopilot's body rates start carrying the attitude through a gap
    (:meth:`~companion.nav.blend.BlendNavigator.hold_attitude`), the rotation under way
    leaves an attitude error along it: the rate (rad/s) times this, s, as a 1-sigma about
    the rate's axis. Beside ArduCopter SITL the rates took over as the copter rolled,
    pitched and yawed out of a corner at about 20 deg/s; the carried attitude settled
    0.3 deg off in roll, pitch and yaw, along that rotation, and stayed so (three flights
    of three, SITL's truth): an effective lag of 30 ms. Its cause is not pinned down: the
    rates trail the attitude by about 10 ms, the IMU's gyros and the rates not at all."""
    rate_drift_window_s: float = ranged(60.0, gt=0.0)
    """Time constant over which the autopilot's attitude is compared with its own body
    rates, s: how far it strays from them bounds their bias when they carry the attitude
    through a gap (:mod:`companion.nav.blend.rate_drift`)."""
    att_err_sigma_rad: tuple[float, float, float] = ranged(
        (0.1 * _DEG, 0.1 * _DEG, 0.5 * _DEG), gt=0.0, length=3
    )
    """Attitude-aided mode: autopilot attitude error 1-sigma about N, E, D axes, rad."""
    att_err_tau_s: float = ranged(60.0, gt=0.0)
    """Attitude-aided mode: correlation time of the autopilot attitude error, s."""
    init_att_sigma_rad: tuple[float, float, float] = ranged(
        (0.5 * _DEG, 0.5 * _DEG, 2.0 * _DEG), gt=0.0, length=3
    )
    """Strapdown mode: initial attitude error 1-sigma about N, E, D, rad."""
    init_vel_sigma_mps: float = ranged(1.0, gt=0.0)
    """Initial velocity 1-sigma when the first fix has none, m/s."""
    align_static_s: float = ranged(1.0, gt=0.0)
    """Own alignment (no autopilot attitude): length of the rest window that levels, s."""
    align_static_acc_std_mps2: float = ranged(0.2, gt=0.0)
    """Own alignment: largest accelerometer standard deviation per axis at rest, m/s^2."""
    align_static_gyro_std_radps: float = ranged(0.5 * _DEG, gt=0.0)
    """Own alignment: largest gyro standard deviation per axis at rest, rad/s."""
    align_window_s: float = ranged(10.0, gt=0.0)
    """Own alignment: window of GNSS velocity changes that yaw is fitted to, s."""
    align_yaw_sigma_max_rad: float = ranged(10.0 * _DEG, gt=0.0)
    """Own alignment: the blend starts once the fitted yaw's 1-sigma is below this, rad."""
    align_tilt_sigma_rad: float = ranged(1.0 * _DEG, gt=0.0)
    """Own alignment: 1-sigma of roll and pitch levelled at rest (accel bias over g), rad."""
    gate_false_alarm_prob: float = ranged(1e-4, gt=0.0, lt=1.0)
    """Probability that a consistent fix fails the innovation chi-square gate."""
    gnss_error_model: str = ranged("gauss_markov", choices=("gauss_markov", "white"))
    """``"gauss_markov"`` (receiver position error as 3 correlated states) or ``"white"``."""
    gnss_white_fraction: float = ranged(0.1, gt=0.0, le=1.0)
    """Gauss-Markov model: share of the reported variance taken as white noise."""
    gnss_err_tau_s: float | None = ranged(None, gt=0.0, optional=True)
    """Gauss-Markov model: correlation time, s (None: per fix type, GNSS_ERR_TAU_S)."""
    pos_std_floor_m: tuple[float, float] = ranged((0.01, 0.015), gt=0.0, length=2)
    """Floor of the horizontal and vertical position measurement 1-sigma, m: set it to what
    the filter's model can honour between fixes (docs/methods.md, "Measurement floors")."""
    vel_std_floor_mps: float = ranged(0.02, gt=0.0)
    """Floor of the velocity measurement 1-sigma, m/s (as ``pos_std_floor_m``)."""
    vel_error_measured: bool = True
    """Add to the receiver's reported horizontal velocity variance what its own position
    increments show its velocity errs beyond it (:mod:`companion.nav.blend.velocity_error`;
    docs/methods.md, "Receiver velocity error measured by its positions")."""
    vel_std_fallback_mps: float = ranged(0.3, gt=0.0)
    """Velocity 1-sigma used when the receiver reported none, m/s."""
    r_scale_bounds: tuple[float, float] = ranged((1.0, 20.0), gt=0.0, finite=False, length=2)
    """Bounds of the adaptive scale on the reported measurement variances. The default
    floor 1 never lets R fall below what the receiver reports (see the module docstring)."""
    q_scale_bounds: tuple[float, float] = ranged((1.0, 100.0), gt=0.0, finite=False, length=2)
    """Bounds of the adaptive accelerometer noise PSD, as multiples of the configured one
    (default floor 1: never below the IMU's specification)."""
    cov_interval_s: float = ranged(0.1, gt=0.0)
    """Covariance propagation interval, s (the nominal state advances per IMU sample)."""
    cov_discretisation: str = ranged("second_order", choices=("second_order", "van_loan"))
    """``"second_order"`` (Phi to second order, trapezoidal Qd: third-order error in
    ||F|| dt, about 1e-3 relative at 0.1 s) or ``"van_loan"`` (exact for constant F)."""
    history_s: float = ranged(1.5, gt=0.0)
    """Length of the state/covariance ring buffer: the oldest fix time that can be fused, s."""
    max_imu_gap_s: float = ranged(0.5, gt=0.0)
    """IMU gaps longer than this are integrated but counted and logged, s."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.adaptive_min_epochs > self.adaptive_window:
            raise ValueError(
                f"adaptive_min_epochs must be <= adaptive_window ({self.adaptive_window}), "
                f"got {self.adaptive_min_epochs}"
            )
        for name in ("r_scale_bounds", "q_scale_bounds"):
            lo, hi = getattr(self, name)
            if not lo <= 1.0 <= hi:
                raise ValueError(f"{name} must satisfy low <= 1 <= high, got {(lo, hi)}")
        if self.history_s < 2.0 * self.cov_interval_s:
            raise ValueError(
                f"history_s must be >= 2 cov_interval_s ({2.0 * self.cov_interval_s:g}), "
                f"got {self.history_s}"
            )

    @property
    def heading_prior_sigma_rad(self) -> float:
        """The 1-sigma the blend gives the autopilot's heading error before any taxi
        correction (the attitude error about down its mode starts from), rad."""
        sigma = self.init_att_sigma_rad if self.mode == "strapdown" else self.att_err_sigma_rad
        return float(sigma[2])

    @classmethod
    def for_grade(cls, grade: str, **overrides: object) -> BlendConfig:
        """Noise densities of an IMU grade from :data:`companion.nav.grades.IMU_GRADES`:
        ``"tactical"`` (1-10 deg/h gyros, El-Mowafy 2005) or ``"mems"``.

        ``overrides`` replace any other field.
        """
        if grade not in IMU_GRADES or grade == "perfect":
            raise ValueError(f"grade must be one of ['mems', 'tactical'], got {grade!r}")
        g = IMU_GRADES[grade]
        params: dict[str, object] = dict(
            accel_vrw_mps_rts=g.acc_noise_density_mps2_rthz,
            gyro_arw_rad_rts=g.gyro_noise_density_radps_rthz,
            accel_bias_sigma_mps2=g.acc_bias_sigma_mps2,
            gyro_bias_sigma_radps=g.gyro_bias_sigma_radps,
            gyro_instability_radps=g.gyro_instability_radps,
        )
        params.update(overrides)
        return cls(**params)  # type: ignore[arg-type]
