"""Adaptive GNSS/INS blend: an error-state Kalman filter with delayed GNSS fusion (S1).

States (estimate minus truth, see :mod:`companion.nav.ins`): position (0:3, m),
velocity (3:6, m/s), attitude error psi (6:9, rad), accelerometer bias
(9:12, m/s^2), gyro bias (12:15, rad/s), and the receiver's own position
error (15:18, m, see below). Loose coupling as in S1: the GNSS
receiver's position and velocity are the measurements, with R from the
accuracies it reports.

GNSS position errors are time-correlated (an RTK or DGPS error wanders over
tens of seconds; between 5-10 Hz fixes it looks like signal). Treated as
white, they make the filter average them away and claim a position
covariance ten to fifty times too small (NEES 40-65 on the simulator's RTK
approach). So by default (``gnss_error_model="gauss_markov"``) the state also
holds the receiver's position error (states 15:18) as a first-order
Gauss-Markov process of the reported variance and a per-fix-type correlation
time (:data:`GNSS_ERR_TAU_S`), plus a small white part
(``gnss_white_fraction`` of the reported variance, floored); the block is
re-initialised when the fix type changes. ``"white"`` keeps the classical
loose coupling (the reported variance as white R).

Timing (the ArduPilot EKF3 pattern):

* every IMU sample advances the nominal state (plain floats, microseconds);
* every ``cov_interval_s`` (default 0.1 s) the 18x18 covariance is
  propagated once through the segment, with F evaluated at the segment's
  mean NED specific force, discretised to second order (trapezoidal Qd) or
  by Van Loan (``cov_discretisation``); the segment's
  (t, nominal state, P, Phi, Qd) is pushed into a ring buffer of
  ``history_s`` seconds;
* a GNSS fix valid at ``t_m`` (older than the newest IMU sample) is compared
  with the buffered nominal state at ``t_m`` (Hermite interpolation between
  snapshots) using the buffered covariance of the segment containing
  ``t_m``; the correction is carried forward to the newest IMU time through
  the buffered transition matrices (dx_{i+1} = Phi_i dx_i) and the
  covariance re-propagated through the buffered (Phi_i, Qd_i) -- exact for
  the linear error model -- and the buffered snapshots are corrected too.

Adaptive noise (S1, Mohamed & Schwarz 1999). Variant implemented and why:

* R: the **residual form** R = C_v + H P+ H^T, not the innovation form
  R = C_eta - H P- H^T. The innovation form subtracts two comparable
  positive matrices and goes indefinite whenever the window's sample
  covariance happens to be small (common with N = 25 and centimetre RTK);
  the residual form is a sum of positive semi-definite terms, so the
  estimate stays positive by construction and is unbiased at the filter's
  fixed point (E[v v^T] = R - H P+ H^T). It is estimated per position
  component as a **scale on the receiver's reported variance** (the window
  mean of (v_i^2 + (H P+ H^T)_ii) / R_i, R_i the white R the model used;
  the scale multiplies both the white part and the receiver-error states'
  variance), so a step in the reported
  accuracy (RTK fixed -> float) is followed at once instead of after N
  epochs; the scale is bounded (``r_scale_bounds``) and R floored.
* Q: S1's Q = K C_eta K^T is only the first term of Mohamed & Schwarz's
  estimator; the full one, Q = mean(dx dx^T) + P+_k - Phi P+_{k-1} Phi^T,
  equals Q_used + K (eta eta^T - S) K^T per epoch, which is what is
  windowed here. Only its velocity block is used -- the one that the
  accelerometer white noise drives directly -- to re-estimate the
  accelerometer noise density per NED axis, bounded by ``q_scale_bounds``
  times the configured value. Bias and attitude noises stay at their
  configured values (too weakly observable over 25 epochs to adapt).
* Which innovations feed which estimate: R and Q estimated jointly from the
  same innovations are not separately identifiable (Mehra 1972), and on
  simulated flights adapting the velocity R together with Q drifted (Q too
  low, velocity R too high, each excusing the other). So R is adapted from
  the **position** residuals (where R dominates: between 5-10 Hz fixes the
  INS prediction error is far below the receiver noise) and Q from the
  **velocity** innovations, with the receiver's velocity accuracy taken as
  reported (floored).
* Floors: by default neither R nor Q may fall below the receiver's report
  and the IMU specification (``r_scale_bounds`` and ``q_scale_bounds`` start
  at 1). GNSS position errors are time-correlated (RTK and DGPS errors wander
  over tens of seconds): between 5-10 Hz fixes they look like signal, the
  residuals come out far smaller than the true error, and an unfloored
  window shrinks R twenty-fold (measured on the simulator's RTK-fixed
  approach with the white error model), after which the filter follows the wandering error and
  mis-estimates the accelerometer biases that carry the next outage. A
  window can reliably tell only that noise is *larger* than modelled, which
  is also the direction that keeps the bridging covariance honest. With
  white noise (e.g. ``r_scale_bounds=(0.05, 20)``) the estimator follows the
  truth both ways (tests/nav/test_blend.py).

``BlendConfig(adaptive=False)`` is the non-adaptive baseline.

References
----------
SEEDS.md S1 (blend equations, adaptive R and Q, moving window N = 20-30);
Mohamed & Schwarz, J. Geodesy 73 (1999) eq. 20-28; Mehra, "Approaches to adaptive
filtering", IEEE TAC 17(5), 1972 (identifiability of Q and R); Van Loan (1978);
ArduPilot AP_NavEKF3 (fusion at the delayed horizon, output predictor).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from companion.nav import ins
from companion.nav.frames import LocalFrame
from companion.nav.gnss import FALLBACK_STD_M, UNKNOWN_STD_M
from companion.nav.grades import IMU_GRADES
from companion.nav.kalman import (
    Correction,
    InnovationWindow,
    chi2_gate,
    discretise_second_order,
    joseph_update_diag_r,
    predict_covariance,
    van_loan,
)
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState, rotation_between_frames
from companion.nav.rotations import (
    Mat3Values,
    Quat,
    Vec3,
    euler_to_quat_values,
    mat_to_quat,
    quat_from_rotvec,
    quat_mul,
    quat_normalise,
    quat_to_mat,
    quat_to_mat_values,
    quat_to_yaw,
    rotate_by_rotvec,
    skew,
    wrap_pi,
)
from companion.types import AttitudeSample, FixType, FloatArray, ImuSample

log = logging.getLogger(__name__)

_DEG = math.pi / 180.0
_HOUR_S = 3600.0

GNSS_ERR_TAU_S: dict[FixType, float] = {
    FixType.RTK_FIXED: 30.0,
    FixType.RTK_FLOAT: 60.0,
    FixType.DGPS: 120.0,
    FixType.FIX_3D: 300.0,
    FixType.FIX_2D: 300.0,
    FixType.STATIC: 30.0,
    FixType.PPP: 120.0,
}
"""Correlation time (s) of the receiver's position error per fix type: multipath and
residual atmospheric errors wander over tens of seconds to minutes; the order of magnitude
matters more than the figure (see the module docstring)."""

N_STATE = ins.N_ERR + 3
"""Blend state size: the 15 INS error states and the GNSS position error (15:18, NED, m)."""
IGB = ins.N_ERR


@dataclass(frozen=True, slots=True)
class BlendConfig:
    """Configuration of :class:`BlendNavigator` (SI units; noise densities per sqrt(s))."""

    mode: str = "attitude_aided"
    """``"attitude_aided"`` (autopilot ATTITUDE rotates the specific force) or ``"strapdown"``."""
    adaptive: bool = True
    """Adaptive R and Q (S1); False gives the non-adaptive baseline."""
    adaptive_window: int = 25
    """Moving-window length N in GNSS epochs (S1: 20-30)."""
    adaptive_min_epochs: int = 10
    """Epochs in the window before the adaptive estimates are used."""
    lever_arm_b_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """GNSS antenna position relative to the IMU, body FRD axes, m."""
    accel_vrw_mps_rts: float = 0.03 / 60.0
    """Accelerometer white noise (velocity random walk), m/s/sqrt(s)."""
    gyro_arw_rad_rts: float = 0.05 * _DEG / 60.0
    """Gyro white noise (angle random walk), rad/sqrt(s)."""
    accel_bias_sigma_mps2: float = 1e-3 * 9.80665
    """Accelerometer bias 1-sigma (Gauss-Markov steady state), m/s^2."""
    accel_bias_tau_s: float = 3600.0
    """Accelerometer bias correlation time, s (inf = random constant + walk)."""
    gyro_bias_sigma_radps: float = 5.0 * _DEG / _HOUR_S
    """Gyro bias 1-sigma, rad/s."""
    gyro_bias_tau_s: float = 3600.0
    """Gyro bias correlation time, s."""
    att_err_sigma_rad: tuple[float, float, float] = (0.1 * _DEG, 0.1 * _DEG, 0.5 * _DEG)
    """Attitude-aided mode: autopilot attitude error 1-sigma about N, E, D axes, rad."""
    att_err_tau_s: float = 60.0
    """Attitude-aided mode: correlation time of the autopilot attitude error, s."""
    init_att_sigma_rad: tuple[float, float, float] = (0.5 * _DEG, 0.5 * _DEG, 2.0 * _DEG)
    """Strapdown mode: initial attitude error 1-sigma about N, E, D, rad."""
    init_vel_sigma_mps: float = 1.0
    """Initial velocity 1-sigma when the first fix has none, m/s."""
    gate_false_alarm_prob: float = 1e-4
    """Probability that a consistent fix fails the innovation chi-square gate."""
    gnss_error_model: str = "gauss_markov"
    """``"gauss_markov"`` (receiver position error as 3 correlated states) or ``"white"``."""
    gnss_white_fraction: float = 0.1
    """Gauss-Markov model: share of the reported variance taken as white noise."""
    gnss_err_tau_s: float | None = None
    """Gauss-Markov model: correlation time, s (None: per fix type, GNSS_ERR_TAU_S)."""
    pos_std_floor_m: tuple[float, float] = (0.01, 0.015)
    """Floor of the horizontal and vertical position measurement 1-sigma, m."""
    vel_std_floor_mps: float = 0.02
    """Floor of the velocity measurement 1-sigma, m/s."""
    vel_std_fallback_mps: float = 0.3
    """Velocity 1-sigma used when the receiver reported none, m/s."""
    r_scale_bounds: tuple[float, float] = (1.0, 20.0)
    """Bounds of the adaptive scale on the reported measurement variances. The default
    floor 1 never lets R fall below what the receiver reports (see the module docstring)."""
    q_scale_bounds: tuple[float, float] = (1.0, 100.0)
    """Bounds of the adaptive accelerometer noise PSD, as multiples of the configured one
    (default floor 1: never below the IMU's specification)."""
    cov_interval_s: float = 0.1
    """Covariance propagation interval, s (the nominal state advances per IMU sample)."""
    cov_discretisation: str = "second_order"
    """``"second_order"`` (Phi to second order, trapezoidal Qd: third-order error in
    ||F|| dt, about 1e-3 relative at 0.1 s) or ``"van_loan"`` (exact for constant F)."""
    history_s: float = 1.5
    """Length of the state/covariance ring buffer: the oldest fix time that can be fused, s."""
    max_imu_gap_s: float = 0.5
    """IMU gaps longer than this are integrated but counted and logged, s."""

    def __post_init__(self) -> None:
        if self.mode not in ("attitude_aided", "strapdown"):
            raise ValueError(f"mode must be 'attitude_aided' or 'strapdown', got {self.mode!r}")
        if not 2 <= self.adaptive_window <= 1000:
            raise ValueError("adaptive_window must be in [2, 1000]")
        if not 1 <= self.adaptive_min_epochs <= self.adaptive_window:
            raise ValueError("adaptive_min_epochs must be in [1, adaptive_window]")
        if len(self.lever_arm_b_m) != 3 or not all(math.isfinite(c) for c in self.lever_arm_b_m):
            raise ValueError("lever_arm_b_m must be 3 finite numbers")
        for name in (
            "accel_vrw_mps_rts",
            "gyro_arw_rad_rts",
            "accel_bias_sigma_mps2",
            "accel_bias_tau_s",
            "gyro_bias_sigma_radps",
            "gyro_bias_tau_s",
            "att_err_tau_s",
            "init_vel_sigma_mps",
            "vel_std_floor_mps",
            "vel_std_fallback_mps",
            "cov_interval_s",
            "history_s",
            "max_imu_gap_s",
        ):
            value = getattr(self, name)
            if not value > 0.0 or math.isnan(value):
                raise ValueError(f"{name} must be > 0, got {value}")
        for name in ("att_err_sigma_rad", "init_att_sigma_rad", "pos_std_floor_m"):
            value = getattr(self, name)
            if not all(c > 0.0 and math.isfinite(c) for c in value):
                raise ValueError(f"{name} must hold positive finite numbers, got {value}")
        if not 0.0 < self.gate_false_alarm_prob < 1.0:
            raise ValueError("gate_false_alarm_prob must be in (0, 1)")
        for name in ("r_scale_bounds", "q_scale_bounds"):
            lo, hi = getattr(self, name)
            if not 0.0 < lo <= 1.0 <= hi:
                raise ValueError(f"{name} must satisfy 0 < low <= 1 <= high, got {(lo, hi)}")
        if self.gnss_error_model not in ("gauss_markov", "white"):
            raise ValueError(
                f"gnss_error_model must be 'gauss_markov' or 'white', got {self.gnss_error_model!r}"
            )
        if not 0.0 < self.gnss_white_fraction <= 1.0:
            raise ValueError("gnss_white_fraction must be in (0, 1]")
        if self.gnss_err_tau_s is not None and not (
            math.isfinite(self.gnss_err_tau_s) and self.gnss_err_tau_s > 0.0
        ):
            raise ValueError("gnss_err_tau_s must be a positive finite number or None")
        if self.cov_discretisation not in ("second_order", "van_loan"):
            raise ValueError(
                f"cov_discretisation must be 'second_order' or 'van_loan', "
                f"got {self.cov_discretisation!r}"
            )
        if self.history_s < 2.0 * self.cov_interval_s:
            raise ValueError("history_s must be at least twice cov_interval_s")

    @classmethod
    def for_grade(cls, grade: str, **overrides: object) -> BlendConfig:
        """Noise densities of an IMU grade: ``"tactical"`` (1-10 deg/h gyros, S1) or ``"mems"``.

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
        )
        params.update(overrides)
        return cls(**params)  # type: ignore[arg-type]


@dataclass(slots=True)
class _Snapshot:
    """Nominal state and covariance at a segment boundary, with the segment that follows."""

    t_s: float
    pos: tuple[float, ...]
    """Nominal position (3 floats, NED, m)."""
    vel: tuple[float, ...]
    """Nominal velocity (3 floats, NED, m/s)."""
    q_nb: Quat
    p_mat: FloatArray
    phi: FloatArray | None = None
    qd: FloatArray | None = None


@dataclass(slots=True)
class BlendDiagnostics:
    """What the last GNSS update saw and the adaptive estimates now in use."""

    r_scale: FloatArray = field(default_factory=lambda: np.ones(6))
    """Adaptive scale on the reported variance per component (pos N, E, D, vel N, E, D);
    the velocity components stay at 1 (see the module docstring)."""
    r_used: FloatArray = field(default_factory=lambda: np.full(6, np.nan))
    """Measurement variances used at the last update, (6,), NaN for absent components."""
    accel_psd_ned: FloatArray = field(default_factory=lambda: np.zeros(3))
    """Accelerometer white-noise PSD in use per NED axis, m^2/s^3."""
    last_nis: float = math.nan
    last_dof: int = 0
    fused: int = 0
    gated: int = 0
    rejected: dict[str, int] = field(default_factory=dict)


class BlendNavigator:
    """Adaptive GNSS/INS blend (implements :class:`companion.nav.navigator.Navigator`).

    ``frame`` is the engine's local frame, used for the gravity model; it is
    updated by :meth:`shift_frame`. Positions are of the IMU reference point.
    """

    def __init__(self, config: BlendConfig | None = None, frame: LocalFrame | None = None) -> None:
        self.config = config or BlendConfig()
        self._frame = frame or LocalFrame(45.0 * _DEG, 0.0, 0.0)
        if frame is None:
            log.warning("no local frame given: gravity evaluated at 45 deg latitude, 0 m")
        self._strapdown = self.config.mode == "strapdown"
        self._lever = np.array(self.config.lever_arm_b_m, dtype=float)
        self._has_lever = bool(np.any(self._lever != 0.0))
        self._gates = {m: chi2_gate(self.config.gate_false_alarm_prob, m) for m in range(1, 7)}
        self._accel_psd0 = self.config.accel_vrw_mps_rts**2
        cfg = self.config
        h_fl, v_fl = cfg.pos_std_floor_m
        self._pos_floor_t = (h_fl**2, h_fl**2, v_fl**2)
        # variances assumed when the receiver reports none (FALLBACK_STD_M squared)
        self._pos_fallback = {
            fix: (h_std**2, h_std**2, v_std**2) for fix, (h_std, v_std) in FALLBACK_STD_M.items()
        }
        h_un, v_un = UNKNOWN_STD_M
        self._pos_fallback_other = (h_un**2, h_un**2, v_un**2)
        self._vel_fallback_floor = (cfg.vel_std_fallback_mps**2, cfg.vel_std_floor_mps**2)
        self._h_cache: dict[tuple[bool, ...], tuple[tuple[int, ...], FloatArray]] = {}
        self._gm = cfg.gnss_error_model == "gauss_markov"
        self._max_imu_gap_s = cfg.max_imu_gap_s
        self._cov_interval_s = cfg.cov_interval_s
        self._gqg_static = self._static_gqg()
        self._f_template = np.zeros((N_STATE, N_STATE))
        self._f_template[: ins.N_ERR, : ins.N_ERR] = ins.error_model_f(
            np.zeros(3),
            np.zeros((3, 3)),
            strapdown=self._strapdown,
            tau_att_s=cfg.att_err_tau_s,
            tau_ba_s=cfg.accel_bias_tau_s,
            tau_bg_s=cfg.gyro_bias_tau_s,
        )
        self._f_flat = self._f_template.reshape(-1)  # a view: writes fill the template
        self._f_idx = _flat_index(
            _F_VARIABLE_ENTRIES + (_F_STRAPDOWN_ENTRIES if self._strapdown else [])
        )
        self._van_loan = cfg.cov_discretisation == "van_loan"
        self.reset()

    # ------------------------------------------------------------------ protocol

    @property
    def initialised(self) -> bool:
        """True once a state exists (after the first accepted fix with an attitude)."""
        return self._init

    def reset(self) -> None:
        """Forget everything (the configuration and frame are kept)."""
        self._mech = ins.Mechanisation(ins.LocalGravity(self._frame.lat0_rad, self._frame.alt0_m))
        self._init = False
        self._pre_imu: deque[tuple[float, list[float], list[float]]]
        self._pre_imu = deque()
        self._p = np.zeros((N_STATE, N_STATE))
        self._gb = [0.0, 0.0, 0.0]
        self._gb_var = np.zeros(3)
        self._gb_var_l = [0.0, 0.0, 0.0]
        self._r_scale_last: list[float] | None = None
        self._gb_fix: FixType | None = None
        self._gb_tau = 300.0
        self._hist: deque[_Snapshot] = deque()
        self._att_q: Quat | None = None
        self._att_t_s = math.nan
        self._att_corr: Quat = (1.0, 0.0, 0.0, 0.0)
        self._last_fuse_t_s = math.nan
        self._r_win = InnovationWindow(3, self.config.adaptive_window)
        self._q_win = InnovationWindow(3, self.config.adaptive_window)
        self.diag = BlendDiagnostics(accel_psd_ned=np.full(3, self._accel_psd0))
        self._gqg = self._make_gqg()

    def on_imu(self, sample: ImuSample) -> None:
        """Advance the nominal state with one IMU sample; propagate P every ``cov_interval_s``."""
        acc_t = sample.acc_b_mps2.tolist()
        gyro_t = sample.gyro_b_radps.tolist()
        if len(acc_t) != 3 or len(gyro_t) != 3:
            self._reject("imu_bad_shape")
            return
        if not math.isfinite(sum(acc_t) + sum(gyro_t)):  # NaN or inf makes the sum non-finite
            self._reject("imu_not_finite")
            return
        mech = self._mech
        if not self._init:
            if self._pre_imu and sample.t_s <= self._pre_imu[-1][0]:
                if sample.t_s > self._pre_imu[-1][0] - self.config.max_imu_gap_s:
                    self._reject("imu_time_not_increasing")
                    return
                self._reject("imu_clock_restarted")  # a new clock: start the buffer again
                self._pre_imu.clear()
            self._pre_imu.append((sample.t_s, acc_t, gyro_t))
            while self._pre_imu[0][0] < sample.t_s - self.config.history_s:
                self._pre_imu.popleft()
            mech.set_raw(acc_t, gyro_t)
            mech.t_s = sample.t_s
            return
        dt = sample.t_s - mech.t_s
        if dt <= 0.0:
            self._reject("imu_time_not_increasing")
            return
        if dt > self._max_imu_gap_s:
            self._reject("imu_gap")
        mech.step(sample.t_s, acc_t, gyro_t)
        if mech.seg_dt_s >= self._cov_interval_s:
            self._close_segment()

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        """A taxi heading correction (S4) was applied to the attitude input: restart the
        heading from the corrected autopilot yaw, 1-sigma ``yaw_sigma_rad``.

        Attitude-aided: the filter's own yaw correction estimated part of the error the
        S4 correction has now removed from the input; kept, it would correct twice.
        Strapdown: the mechanisation's yaw is set to the corrected autopilot yaw.
        Either way the yaw error's covariance restarts at ``yaw_sigma_rad``, uncorrelated.
        """
        if not (math.isfinite(yaw_sigma_rad) and yaw_sigma_rad > 0.0):
            raise ValueError("yaw_sigma_rad must be finite and > 0")
        if not self._init or self._att_q is None:
            return
        mech = self._mech
        if self._strapdown:
            target_yaw = quat_to_yaw(*self._att_q)
            yaw = quat_to_yaw(*mech.q_nb)
            turn = wrap_pi(target_yaw - yaw)
        else:
            w, x, y, z = self._att_corr
            sign = 1.0 if w >= 0.0 else -1.0
            # the correction's rotation about down (small-angle rotation vector)
            turn = -2.0 * sign * z
            self._att_corr = quat_normalise(
                quat_mul(quat_from_rotvec(0.0, 0.0, turn), self._att_corr)
            )
        mech.q_nb = rotate_by_rotvec(mech.q_nb, 0.0, 0.0, turn)
        k = ins.IA + 2
        p = self._p
        p[k, :] = 0.0
        p[:, k] = 0.0
        p[k, k] = yaw_sigma_rad**2
        for snap in self._hist:
            snap.q_nb = rotate_by_rotvec(snap.q_nb, 0.0, 0.0, turn)
        log.info("heading restarted from the taxi correction: turned %.3f deg", math.degrees(turn))

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        """Take the autopilot's attitude (yaw less ``yaw_correction_rad``).

        Attitude-aided mode: it replaces the attitude (after the filter's own
        estimated correction), carried by the gyro to the newest IMU time.
        Strapdown mode: used only to initialise.
        """
        roll, pitch, yaw = sample.roll_rad, sample.pitch_rad, sample.yaw_rad
        isfinite = math.isfinite
        if not (
            isfinite(roll) and isfinite(pitch) and isfinite(yaw) and isfinite(yaw_correction_rad)
        ):
            self._reject("attitude_not_finite")
            return
        self._att_q = euler_to_quat_values(roll, pitch, yaw - yaw_correction_rad)
        self._att_t_s = sample.t_s
        if self._init and not self._strapdown:
            mech = self._mech
            q_used = quat_mul(self._att_corr, self._att_q)
            mech.q_nb = mech.carry_attitude(q_used, mech.t_s - sample.t_s)

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Gate and fuse one fix at its own time; carry the correction to the newest IMU time."""
        cfg = self.config
        z_pos = meas.pos_ned_m.tolist()
        if not (all(map(math.isfinite, z_pos)) and math.isfinite(meas.t_s)):
            return self._refuse(meas, "position_not_finite")
        r_pos_rep, r_vel_rep = self._reported_variances(meas)
        if not self._init:
            return self._initialise(meas, r_pos_rep, r_vel_rep)
        mech = self._mech
        if meas.t_s > mech.t_s + cfg.cov_interval_s:
            return self._refuse(meas, "fix_ahead_of_imu")
        if self._hist and meas.t_s < self._hist[0].t_s - cfg.cov_interval_s:
            return self._refuse(meas, "fix_older_than_history")
        if math.isfinite(self._last_fuse_t_s) and meas.t_s <= self._last_fuse_t_s - 1e-9:
            return self._refuse(meas, "fix_out_of_order")

        # per-fix vectors of 3 to 6 components are Python floats here (a numpy call costs
        # more than the arithmetic); the same operations as the array forms, so the same values
        scale = self._r_scale()
        r_pos_scaled = [r * k for r, k in zip(r_pos_rep, scale, strict=True)]
        self._gnss_error_block(meas.fix_type, r_pos_scaled)
        idx, pos_m, vel_m, q_m = self._state_at(meas.t_s)
        snap = self._hist[idx]
        p_m = snap.p_mat
        dt_p = meas.t_s - snap.t_s
        if dt_p > 0.0:
            # the snapshot's covariance is up to cov_interval_s older than the fix: carry it
            # (negligible in steady flight, not while the velocity is uncertain: after the
            # first fix, where GPS_RAW_INT gives no vertical velocity, and after an outage)
            p_m = _carry_pos_vel(p_m, dt_p, self.diag.accel_psd_ned)
        axes, y, h_mat, r_rep = self._measurement(
            meas, z_pos, pos_m, vel_m, q_m, r_pos_rep, r_vel_rep
        )
        if self._gm:  # the white part of the position noise; the rest is in states 15:18
            r_rep[:3] = self._white_part(r_pos_rep)
        # the adaptive scale is on the position components (the velocity components' is 1)
        r_diag = [r_rep[0] * scale[0], r_rep[1] * scale[1], r_rep[2] * scale[2], *r_rep[3:]]
        dof = len(y)
        threshold = self._gates[dof]
        y_arr = np.array(y)
        try:
            corr = joseph_update_diag_r(p_m, y_arr, h_mat, np.array(r_diag))
        except ValueError:
            return self._refuse(meas, "innovation_cov_not_pd")
        innov_pos = -y_arr[:3]
        s_pos = corr.innov_cov[:3, :3]
        self.diag.last_nis = corr.nis
        self.diag.last_dof = dof
        if gate and corr.nis > threshold:
            self.diag.gated += 1
            log.debug("fix %.3f gated: NIS %.1f > %.1f", meas.t_s, corr.nis, threshold)
            return GnssUpdate(meas.t_s, False, corr.nis, dof, threshold, innov_pos, s_pos, "gate")

        d = corr.dx.tolist()
        if cfg.adaptive:
            self._adapt(y, axes, h_mat, r_rep, p_m, corr, d, meas.t_s)
        r_used = [*r_pos_scaled, math.nan, math.nan, math.nan]
        for k, axis in enumerate(axes):
            r_used[3 + axis] = r_diag[3 + k]
        self.diag.r_used = np.array(r_used)
        # the correction is for the fix time; injected at the snapshot, its position part
        # moves with its velocity part over the time between them (a 2 m/s correction
        # 0.05 s away would otherwise plant 0.1 m of position error)
        lag = snap.t_s - meas.t_s
        d[0] += lag * d[3]
        d[1] += lag * d[4]
        d[2] += lag * d[5]
        self._apply(idx, d, corr.p_post)
        self._last_fuse_t_s = meas.t_s
        self.diag.fused += 1
        return GnssUpdate(meas.t_s, True, corr.nis, dof, threshold, innov_pos, s_pos)

    def predict(self, t_s: float) -> NavState | None:
        """The state carried from the newest IMU time to ``t_s`` (constant velocity), unchanged."""
        if not self._init:
            return None
        mech = self._mech
        dt = max(0.0, t_s - mech.t_s)
        # covariance at the newest IMU time: the last propagated P plus the open segment
        dt_p = max(0.0, t_s - self._hist[-1].t_s)
        cov = _open_segment_cov(self._p[0:6, 0:6].tolist(), self.diag.accel_psd_ned.tolist(), dt_p)
        w, x, y, z = mech.q_nb
        yaw = quat_to_yaw(w, x, y, z)
        vn, ve, vd = mech.vel
        pn, pe, pd = mech.pos
        if dt > 0.0:
            # carry the heading with the latest body rate (turns at 10 deg/s move it
            # 0.2 deg in one 50 Hz IMU period): the down row of mat_nb times the rate
            g = mech.last_gyro_b_radps
            bg = mech.bg
            yaw_rate = (
                2 * (x * z - w * y) * (g[0] - bg[0])
                + 2 * (y * z + w * x) * (g[1] - bg[1])
                + (1 - 2 * (x * x + y * y)) * (g[2] - bg[2])
            )
            yaw = wrap_pi(yaw + yaw_rate * dt)
        # one array each for the vectors and the covariances (views of them in the state)
        pos_vel = np.array((pn + vn * dt, pe + ve * dt, pd + vd * dt, vn, ve, vd))
        cov_pv = np.array(cov).reshape(2, 3, 3)
        return NavState(t_s, pos_vel[0:3], pos_vel[3:6], cov_pv[0], cov_pv[1], yaw)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express the state in ``new`` (position through geodetic, vectors rotated)."""
        self._frame = new
        self._mech.set_gravity(ins.LocalGravity(new.lat0_rad, new.alt0_m))
        if not self._init:
            return
        if self._mech.seg_dt_s > 0.0:
            self._close_segment()
        rot = rotation_between_frames(old, new)
        mech = self._mech
        lat, lon, alt = old.ned_to_lla(np.array(mech.pos))
        mech.pos = [float(c) for c in new.lla_to_ned(lat, lon, alt)]
        mech.vel = [float(c) for c in rot @ np.array(mech.vel)]
        q_rot = mat_to_quat(rot)
        mech.q_nb = quat_normalise(quat_mul(q_rot, mech.q_nb))
        t = np.eye(N_STATE)
        self._gb = (rot @ np.array(self._gb)).tolist()
        for k in (ins.IP, ins.IV, ins.IA, IGB):
            t[k : k + 3, k : k + 3] = rot
        self._p = t @ self._p @ t.T
        self._att_corr = quat_normalise(quat_mul(q_rot, self._att_corr))
        self._hist = deque(
            [_Snapshot(mech.t_s, tuple(mech.pos), tuple(mech.vel), mech.q_nb, self._p)]
        )
        self._last_fuse_t_s = math.nan

    # ------------------------------------------------------------------ diagnostics

    @property
    def r_estimate(self) -> FloatArray:
        """Measurement variances of the last update (pos N, E, D, vel N, E, D), (6,)."""
        return self.diag.r_used.copy()

    @property
    def q_estimate_accel_psd(self) -> FloatArray:
        """Accelerometer white-noise PSD in use per NED axis, m^2/s^3, (3,)."""
        return self.diag.accel_psd_ned.copy()

    @property
    def covariance(self) -> FloatArray:
        """Error-state covariance at the last covariance epoch, (15, 15)."""
        return self._p.copy()

    @property
    def biases(self) -> tuple[FloatArray, FloatArray]:
        """Accelerometer (m/s^2) and gyro (rad/s) bias estimates, body axes, (3,) each."""
        return np.array(self._mech.ba), np.array(self._mech.bg)

    @property
    def attitude_q_nb(self) -> FloatArray:
        """Body-to-NED quaternion (w, x, y, z) in use, (4,)."""
        return np.array(self._mech.q_nb)

    @property
    def imu_t_s(self) -> float:
        """Time of the newest IMU sample integrated, s."""
        return self._mech.t_s

    # ------------------------------------------------------------------ internals

    def _reject(self, reason: str) -> None:
        rej = self.diag.rejected
        rej[reason] = rej.get(reason, 0) + 1
        if rej[reason] in (1, 10, 100, 1000) or rej[reason] % 10000 == 0:
            log.warning("blend rejected input (%s), %d so far", reason, rej[reason])

    def _refuse(self, meas: GnssMeasurement, reason: str) -> GnssUpdate:
        self._reject(reason)
        nan3 = np.full(3, np.nan)
        return GnssUpdate(
            meas.t_s, False, math.nan, 0, math.nan, nan3, np.full((3, 3), np.nan), reason
        )

    def _static_gqg(self) -> FloatArray:
        """The configuration's part of :meth:`_make_gqg` (attitude and bias noises), (18,)."""
        cfg = self.config
        g = np.zeros(N_STATE)
        if self._strapdown:
            g[6:9] = cfg.gyro_arw_rad_rts**2
        else:
            sig = np.array(cfg.att_err_sigma_rad)
            g[6:9] = 2.0 * sig**2 / cfg.att_err_tau_s
        g[9:12] = _gm_psd(cfg.accel_bias_sigma_mps2, cfg.accel_bias_tau_s)
        g[12:15] = _gm_psd(cfg.gyro_bias_sigma_radps, cfg.gyro_bias_tau_s)
        return g

    def _make_gqg(self) -> FloatArray:
        """Diagonal (18,) of the continuous noise intensity G Qc G^T with the current accel
        PSD and receiver-error block."""
        g = self._gqg_static.copy()
        g[3:6] = self.diag.accel_psd_ned
        if self._gm and self._gb_fix is not None:
            g[IGB : IGB + 3] = 2.0 * self._gb_var / self._gb_tau
        return g

    def _f_filled(self, f_ned: Vec3, mat_nb: Mat3Values) -> FloatArray:
        """F (18, 18) of :func:`companion.nav.ins.error_model_f` (and the receiver-error
        block), filled in place into the preallocated template and returned (a view that
        the next call overwrites). ``mat_nb`` is row-major (9 floats)."""
        f0, f1, f2 = f_ned
        c00, c01, c02, c10, c11, c12, c20, c21, c22 = mat_nb
        values = [-f2, f1, f2, -f0, -f1, f0, -c00, -c01, -c02, -c10, -c11, -c12, -c20, -c21, -c22]
        if self._strapdown:
            values += mat_nb
        # one indexed assignment instead of a dozen element writes
        self._f_flat[self._f_idx] = values
        return self._f_template

    def _close_segment(self) -> None:
        """Propagate P over the accumulated segment and push a snapshot."""
        mech = self._mech
        dt, f_ned = mech.take_segment_values()
        snap = self._hist[-1]
        mat_nb = quat_to_mat_values(mech.q_nb)
        f_mat = self._f_filled(f_ned, mat_nb)
        if self._van_loan:
            phi, qd = van_loan(f_mat, np.diag(self._gqg), dt)
        else:
            phi, qd = discretise_second_order(f_mat, self._gqg, dt)
        snap.phi, snap.qd = phi, qd
        self._p = predict_covariance(self._p, phi, qd)
        self._hist.append(_Snapshot(mech.t_s, tuple(mech.pos), tuple(mech.vel), mech.q_nb, self._p))
        horizon = mech.t_s - self.config.history_s
        while len(self._hist) > 2 and self._hist[1].t_s <= horizon:
            self._hist.popleft()

    def _state_at(self, t_s: float) -> tuple[int, list[float], list[float], Quat]:
        """Nominal position, velocity (3 floats each) and attitude interpolated at ``t_s``, and
        the index of the snapshot nearest in time (whose covariance the fix is fused with)."""
        hist = self._hist
        mech = self._mech
        n = len(hist)
        j = n - 1
        while j > 0 and hist[j].t_s > t_s:
            j -= 1
        s0 = hist[j]
        s1_pos: Sequence[float]
        s1_vel: Sequence[float]
        if j + 1 < n:
            s1 = hist[j + 1]
            s1_t, s1_pos, s1_vel, s1_q = s1.t_s, s1.pos, s1.vel, s1.q_nb
        else:
            s1_t, s1_pos, s1_vel, s1_q = mech.t_s, mech.pos, mech.vel, mech.q_nb
            if t_s > s1_t:
                return j, *self._extrapolated(t_s)
        h = s1_t - s0.t_s
        u = min(max((t_s - s0.t_s) / h, 0.0), 1.0) if h > 1e-9 else 1.0
        # cubic Hermite position from the end velocities; velocity linear
        u2, u3 = u**2, u**3
        a = 2 * u3 - 3 * u2 + 1
        b = (u3 - 2 * u2 + u) * h
        c = -2 * u3 + 3 * u2
        d = (u3 - u2) * h
        p0, v0, p1, v1 = s0.pos, s0.vel, s1_pos, s1_vel
        w0 = 1.0 - u
        pos = [
            a * p0[0] + b * v0[0] + c * p1[0] + d * v1[0],
            a * p0[1] + b * v0[1] + c * p1[1] + d * v1[1],
            a * p0[2] + b * v0[2] + c * p1[2] + d * v1[2],
        ]
        vel = [w0 * v0[0] + u * v1[0], w0 * v0[1] + u * v1[1], w0 * v0[2] + u * v1[2]]
        if u >= 0.5 and j + 1 < n:
            return j + 1, pos, vel, s1_q
        return j, pos, vel, (s0.q_nb if u < 0.5 else s1_q)

    def _extrapolated(self, t_s: float) -> tuple[list[float], list[float], Quat]:
        """The state carried past the newest IMU sample to ``t_s``, for a fix ahead of it
        (the IMU stream lags or has just stopped), with the mean acceleration of the
        newest ~0.1 s of the history: at 60 m/s in a 3 m/s^2 turn, a 0.08 s lead left
        uncarried is a 4.8 m position and a 0.24 m/s velocity innovation."""
        mech = self._mech
        ahead = t_s - mech.t_s
        pos, vel = mech.pos, mech.vel
        acc = [0.0, 0.0, 0.0]
        for snap in reversed(self._hist):
            span = mech.t_s - snap.t_s
            if span > 0.5 * self._cov_interval_s:
                acc = [(vel[i] - snap.vel[i]) / span for i in range(3)]
                break
        half = 0.5 * ahead * ahead
        pos_t = [pos[i] + vel[i] * ahead + acc[i] * half for i in range(3)]
        vel_t = [vel[i] + acc[i] * ahead for i in range(3)]
        return pos_t, vel_t, mech.q_nb

    def _white_part(self, r_pos: Sequence[float]) -> list[float]:
        """White share of the reported position variance (floored), 3 floats."""
        frac = self.config.gnss_white_fraction
        f0, f1, f2 = self._pos_floor_t
        return [max(frac * r_pos[0], f0), max(frac * r_pos[1], f1), max(frac * r_pos[2], f2)]

    def _gnss_error_block(self, fix_type: FixType, var: list[float]) -> None:
        """Keep the receiver-error states in step with the fix: variance ``var`` (3 floats) and
        the fix type's correlation time; re-initialise them when the fix type changes or the
        variance jumps by more than 4x (a new error regime, uncorrelated with the old)."""
        if not self._gm:
            return
        old = self._gb_var_l
        jump = False
        small_change = True
        for v, o in zip(var, old, strict=True):
            if v > 4.0 * o or v < 0.25 * o:
                jump = True
            if abs(v - o) > 0.05 * o:
                small_change = False
        if fix_type != self._gb_fix or (jump and self._gb_fix is not None):
            tau = self.config.gnss_err_tau_s or GNSS_ERR_TAU_S.get(fix_type, 300.0)
            self._gb_fix = fix_type
            self._gb_tau = tau
            self._gb = [0.0, 0.0, 0.0]
            self._f_template[IGB : IGB + 3, IGB : IGB + 3] = -np.eye(3) / tau
            var_block = np.diag(var)
            for p in [self._p] + [snap.p_mat for snap in self._hist]:
                p[IGB : IGB + 3, :] = 0.0
                p[:, IGB : IGB + 3] = 0.0
                p[IGB : IGB + 3, IGB : IGB + 3] = var_block
            self._set_gb_var(var)
        elif not small_change:
            self._set_gb_var(var)

    def _set_gb_var(self, var: list[float]) -> None:
        self._gb_var = np.array(var)
        self._gb_var_l = list(var)
        self._gqg = self._make_gqg()

    def _reported_variances(self, meas: GnssMeasurement) -> tuple[list[float], list[float]]:
        """Position and velocity variances (3 floats each): reported, else fallback, floored."""
        fallback = self._pos_fallback.get(meas.fix_type, self._pos_fallback_other)
        r_pos = meas.pos_var_ned_m2.tolist()
        for i, (fb, fl) in enumerate(zip(fallback, self._pos_floor_t, strict=True)):
            r = r_pos[i]
            r_pos[i] = max(r if (math.isfinite(r) and r > 0.0) else fb, fl)
        vel_fb, vel_fl = self._vel_fallback_floor
        r_vel = meas.vel_var_ned_m2ps2.tolist()
        for i, r in enumerate(r_vel):
            r_vel[i] = max(r if (math.isfinite(r) and r > 0.0) else vel_fb, vel_fl)
        return r_pos, r_vel

    def _measurement(
        self,
        meas: GnssMeasurement,
        z_pos: list[float],
        pos: list[float],
        vel: list[float],
        q_nb: Quat,
        r_pos: list[float],
        r_vel: list[float],
    ) -> tuple[tuple[int, ...], list[float], FloatArray, list[float]]:
        """Velocity axes used, y = h(x_hat) - z (m floats: 3 position components, then the
        velocity axes), H (m, 18) (read-only), reported R diagonal (m floats)."""
        vel_z = meas.vel_ned_mps.tolist()
        key = (math.isfinite(vel_z[0]), math.isfinite(vel_z[1]), math.isfinite(vel_z[2]))
        cached = self._h_cache.get(key)
        if cached is None:
            axes_c = tuple(i for i in range(3) if key[i])
            h_c = np.zeros((3 + len(axes_c), N_STATE))
            h_c[0:3, ins.IP : ins.IP + 3] = np.eye(3)
            if self._gm:
                h_c[0:3, IGB : IGB + 3] = np.eye(3)
            for k, axis in enumerate(axes_c):
                h_c[3 + k, ins.IV + axis] = 1.0
            h_c.flags.writeable = False  # shared between fixes
            cached = (axes_c, h_c)
            self._h_cache[key] = cached
        axes, h_mat = cached
        pos_ant: Sequence[float] = pos
        vel_ant: Sequence[float] = vel
        if self._has_lever:
            mat_nb = quat_to_mat(q_nb)
            lever_n = mat_nb @ self._lever
            pos_ant = (np.array(pos) + lever_n).tolist()
            h_mat = h_mat.copy()
            h_mat[0:3, ins.IA : ins.IA + 3] = skew(lever_n)
            omega = np.array(self._mech.last_gyro_b_radps) - np.array(self._mech.bg)
            vel_ant = (np.array(vel) + mat_nb @ np.cross(omega, self._lever)).tolist()
        gb = self._gb
        y = [(pos_ant[i] + gb[i]) - z_pos[i] for i in range(3)]
        y += [vel_ant[a] - vel_z[a] for a in axes]
        r_rep = r_pos + [r_vel[a] for a in axes]
        return axes, y, h_mat, r_rep

    def _r_scale(self) -> list[float]:
        """Adaptive variance scale per position component (ones when not adaptive or not
        ready); the velocity components' scale is 1."""
        cfg = self.config
        if not cfg.adaptive:
            return [1.0, 1.0, 1.0]
        lo, hi = cfg.r_scale_bounds
        ready_mean = self._r_win.ready_mean
        min_epochs = cfg.adaptive_min_epochs
        values = [1.0, 1.0, 1.0]
        for i in range(3):
            mean = ready_mean(i, min_epochs)
            if mean is not None:
                values[i] = min(max(mean, lo), hi)
        if values != self._r_scale_last:  # a new array only when the scale changes
            self.diag.r_scale = np.array(values + [1.0, 1.0, 1.0])
            self._r_scale_last = values
        return values

    def _adapt(
        self,
        y: list[float],
        axes: tuple[int, ...],
        h_mat: FloatArray,
        r_rep: list[float],
        p_prior: FloatArray,
        corr: Correction,
        d: list[float],
        t_s: float,
    ) -> None:
        """Window the residual-form R statistics and the Q correction K (eta eta^T - S) K^T.

        For the optimal gain K S K^T = P- - P+, so the velocity diagonal of the Q
        correction is dx_v^2 - (P- - P+)_vv (dx = K eta): no extra matrix products.
        ``d`` is ``corr.dx`` as floats.
        """
        cfg = self.config
        p_post = corr.p_post
        diag = p_post.diagonal().tolist()
        if self._has_lever:
            h3 = h_mat[:3]
            resid = (np.array(y[:3]) - h3.dot(corr.dx)).tolist()
            hph = ((h3.dot(p_post)) * h3).sum(axis=1).tolist()
        elif self._gm:
            # H's position rows select states i and IGB + i: H dx and diag(H P+ H^T) written
            # out (the same two- and four-term sums as the matrix products, same values;
            # P+ is exactly symmetric, so P+[IGB + i, i] is the offset diagonal's entry)
            off = p_post.diagonal(IGB).tolist()
            resid = [y[i] - (d[i] + d[IGB + i]) for i in range(3)]
            hph = [(diag[i] + off[i]) + (off[i] + diag[IGB + i]) for i in range(3)]
        else:
            resid = [y[i] - d[i] for i in range(3)]
            hph = diag[0:3]
        r_add = self._r_win.add
        for k in range(3):  # position rows come first
            r_add(k, (resid[k] ** 2 + hph[k]) / r_rep[k])
        # Q: velocity block of K (eta eta^T - S) K^T per unit time, added to the PSD in use
        if not (math.isfinite(self._last_fuse_t_s) and t_s > self._last_fuse_t_s):
            return
        dt = t_s - self._last_fuse_t_s
        dp = [p_prior.item(k, k) - diag[k] for k in (3, 4, 5)]
        dxv = d[3:6]
        # an unmodelled noise dQ shows in dx_v only through the part of the velocity error
        # the update removes, (K H)_vv: the raw K (eta eta^T - S) K^T sees dQ (K H)_vv^2
        # (worst on the down axis, which GPS_RAW_INT observes through position only);
        # dividing by it makes the increment unbiased. Floored: an axis the fix barely
        # observes cannot say much about its noise. H's velocity rows select the velocity
        # axes measured, so (K H)_vv is the gain's entry of that row (0 for an axis absent).
        kh = [0.0, 0.0, 0.0]
        gain = corr.gain
        for k, axis in enumerate(axes):
            kh[axis] = gain.item(ins.IV + axis, 3 + k)
        psd = self.diag.accel_psd_ned.tolist()
        lo, hi = cfg.q_scale_bounds
        q0 = self._accel_psd0
        q_lo, q_hi = lo * q0, hi * q0
        min_epochs = cfg.adaptive_min_epochs
        q_win = self._q_win
        new = list(psd)
        changed = False
        for i in range(3):
            kh2 = max(kh[i], _KH_FLOOR) ** 2
            q_win.add(i, psd[i] + (dxv[i] ** 2 - dp[i]) / (dt * kh2))
            mean = q_win.ready_mean(i, min_epochs)
            if mean is not None:
                new[i] = min(max(mean, q_lo), q_hi)
                if abs(new[i] - psd[i]) > 1e-3 * psd[i]:
                    changed = True
        if changed:
            self.diag.accel_psd_ned = np.array(new)
            self._gqg = self._make_gqg()

    def _apply(self, idx: int, d: list[float], p_post: FloatArray) -> None:
        """Carry a correction ``d`` (floats) made at snapshot ``idx`` to the newest IMU time
        through the buffered transitions, correcting the snapshots on the way and the
        nominal state."""
        hist = self._hist
        mech = self._mech
        hist[idx].p_mat = p_post
        _inject_snapshot(hist[idx], d)
        p = p_post
        last = len(hist) - 1
        dt_open = mech.seg_dt_s
        if idx < last or dt_open > 0.0:
            dx = np.array(d)
            for i in range(idx, last):
                s = hist[i]
                if s.phi is None or s.qd is None:
                    raise ValueError("history segment without a transition")
                dx = s.phi @ dx  # (a Van Loan phi is a strided view: kept as @)
                p = predict_covariance(p, s.phi, s.qd)
                hist[i + 1].p_mat = p
                _inject_snapshot(hist[i + 1], dx.tolist())
            # the open segment (shorter than cov_interval_s): first-order carry
            if dt_open > 0.0:
                sm = mech.seg_fn_sum
                f_ned = (sm[0] / dt_open, sm[1] / dt_open, sm[2] / dt_open)
                f_dx = self._f_filled(f_ned, quat_to_mat_values(mech.q_nb)).dot(dx)
                f_dx *= dt_open
                dx = dx + f_dx
            d = dx.tolist()
        self._p = p
        mech.inject_values(d)
        if not self._strapdown:
            self._att_corr = rotate_by_rotvec(self._att_corr, d[6], d[7], d[8])
        if self._gm:
            gb = self._gb
            self._gb = [gb[0] - d[IGB], gb[1] - d[IGB + 1], gb[2] - d[IGB + 2]]

    def _initialise(
        self, meas: GnssMeasurement, r_pos_l: list[float], r_vel_l: list[float]
    ) -> GnssUpdate:
        """Start from the first fix and the latest attitude, at the newest IMU time."""
        cfg = self.config
        r_pos, r_vel = np.array(r_pos_l), np.array(r_vel_l)
        if self._att_q is None:
            return self._refuse(meas, "no_attitude_yet")
        pre = self._pre_imu
        if not pre:
            return self._refuse(meas, "no_imu_yet")
        if meas.t_s < pre[0][0]:
            return self._refuse(meas, "fix_older_than_history")
        mech = self._mech
        # start at the fix time from the IMU reading just before it, then replay the
        # buffered IMU samples up to the newest
        t0 = min(meas.t_s, pre[-1][0])
        before = [x for x in pre if x[0] <= t0]
        mech.set_raw(before[-1][1], before[-1][2])
        q0 = mech.carry_attitude(self._att_q, t0 - self._att_t_s)
        mat_nb = quat_to_mat(q0)
        vel = np.asarray(meas.vel_ned_mps, dtype=float)
        vel_ok = np.isfinite(vel)
        vel0 = np.where(vel_ok, vel, 0.0)
        var_v = np.where(vel_ok, r_vel, cfg.init_vel_sigma_mps**2)
        pos0 = meas.pos_ned_m - mat_nb @ self._lever + vel0 * (t0 - meas.t_s)
        mech.initialise(t0, pos0, vel0, q0)
        p = np.zeros((N_STATE, N_STATE))
        p[0:3, 0:3] = np.diag(r_pos)
        self._gb_fix = None
        if self._gm:
            # the first fix carries the receiver error b: position error = b + w,
            # receiver-error state error = -b (the estimate starts at 0)
            self._p = p
            self._hist.clear()
            self._gnss_error_block(meas.fix_type, r_pos_l)
            var = self._gb_var
            p[0:3, 0:3] = np.diag(var + np.array(self._white_part(r_pos_l)))
            p[0:3, IGB : IGB + 3] = -np.diag(var)
            p[IGB : IGB + 3, 0:3] = -np.diag(var)
        p[3:6, 3:6] = np.diag(var_v)
        att_sig = np.array(cfg.init_att_sigma_rad if self._strapdown else cfg.att_err_sigma_rad)
        p[6:9, 6:9] = np.diag(att_sig**2)
        p[9:12, 9:12] = np.eye(3) * cfg.accel_bias_sigma_mps2**2
        p[12:15, 12:15] = np.eye(3) * cfg.gyro_bias_sigma_radps**2
        self._p = p
        self._att_corr = (1.0, 0.0, 0.0, 0.0)
        self._hist.clear()
        self._hist.append(_Snapshot(t0, tuple(mech.pos), tuple(mech.vel), mech.q_nb, p))
        self._init = True
        self._last_fuse_t_s = meas.t_s
        for t_s, acc, gyro in pre:
            if t_s > t0:
                mech.step(t_s, acc, gyro)
                if mech.seg_dt_s >= cfg.cov_interval_s:
                    self._close_segment()
        pre.clear()
        log.info("blend initialised at t=%.3f s (%s)", meas.t_s, cfg.mode)
        gate3 = self._gates[3]
        return GnssUpdate(meas.t_s, True, 0.0, 3, gate3, np.zeros(3), np.diag(r_pos), "init")


def _gm_psd(sigma: float, tau_s: float) -> float:
    """White-noise PSD driving a first-order Gauss-Markov process of steady-state ``sigma``.

    For ``tau_s = inf`` the bias is a random walk reaching ``sigma`` in one hour.
    """
    if math.isfinite(tau_s):
        return 2.0 * sigma**2 / tau_s
    return sigma**2 / _HOUR_S


def _inject_snapshot(snap: _Snapshot, d: list[float]) -> None:
    """Correct a snapshot's nominal state by the error-state correction ``d`` (floats)."""
    p, v = snap.pos, snap.vel
    snap.pos = (p[0] - d[0], p[1] - d[1], p[2] - d[2])
    snap.vel = (v[0] - d[3], v[1] - d[4], v[2] - d[5])
    snap.q_nb = rotate_by_rotvec(snap.q_nb, d[6], d[7], d[8])


def _block(row: int, col: int) -> list[tuple[int, int]]:
    """The (row, col) entries of the 3x3 block at ``row``, ``col``, row-major."""
    return [(row + i, col + j) for i in range(3) for j in range(3)]


def _flat_index(entries: list[tuple[int, int]]) -> npt.NDArray[np.intp]:
    """Flat indices into an (N_STATE, N_STATE) array of (row, col) entries."""
    return np.array([r * N_STATE + c for r, c in entries], dtype=np.intp)


_F_VARIABLE_ENTRIES = [(3, 7), (3, 8), (4, 6), (4, 8), (5, 6), (5, 7)] + _block(3, 9)
"""Entries of F that change per segment: skew(f) (off-diagonal) and -C (see _f_filled)."""
_F_STRAPDOWN_ENTRIES = _block(6, 12)
"""Strapdown: the C block of the attitude error's gyro-bias coupling."""


def _open_segment_cov(b: list[list[float]], psd: list[float], dt_s: float) -> tuple[float, ...]:
    """Position and velocity covariances carried ``dt_s`` through ``position += velocity dt``
    with white acceleration noise of PSD ``psd`` (3 floats, m^2/s^3) from the 6x6
    position/velocity block ``b`` (nested lists): 18 floats, the symmetrised position
    covariance then the velocity covariance, row-major.

    Per entry (i, j) of the position block: ((P_pv + P_vp) dt + P_pp) + dt^2 P_vv, plus
    psd dt^3 / 3 on the diagonal, then (A + A^T) / 2; the velocity block gains psd dt on its
    diagonal. Written out in floats (once per published state: a dozen numpy calls on 3x3
    arrays cost more than the arithmetic); the same operations as the array form.
    """
    b0, b1, b2, b3, b4, b5 = b
    q0, q1, q2 = psd
    dt2 = dt_s**2
    dt3 = dt_s**3
    a00 = ((b0[3] + b3[0]) * dt_s + b0[0]) + dt2 * b3[3] + q0 * dt3 / 3.0
    a01 = ((b0[4] + b3[1]) * dt_s + b0[1]) + dt2 * b3[4]
    a02 = ((b0[5] + b3[2]) * dt_s + b0[2]) + dt2 * b3[5]
    a10 = ((b1[3] + b4[0]) * dt_s + b1[0]) + dt2 * b4[3]
    a11 = ((b1[4] + b4[1]) * dt_s + b1[1]) + dt2 * b4[4] + q1 * dt3 / 3.0
    a12 = ((b1[5] + b4[2]) * dt_s + b1[2]) + dt2 * b4[5]
    a20 = ((b2[3] + b5[0]) * dt_s + b2[0]) + dt2 * b5[3]
    a21 = ((b2[4] + b5[1]) * dt_s + b2[1]) + dt2 * b5[4]
    a22 = ((b2[5] + b5[2]) * dt_s + b2[2]) + dt2 * b5[5] + q2 * dt3 / 3.0
    s01 = (a01 + a10) * 0.5
    s02 = (a02 + a20) * 0.5
    s12 = (a12 + a21) * 0.5
    return (
        (a00 + a00) * 0.5,
        s01,
        s02,
        s01,
        (a11 + a11) * 0.5,
        s12,
        s02,
        s12,
        (a22 + a22) * 0.5,
        b3[3] + q0 * dt_s,
        b3[4],
        b3[5],
        b4[3],
        b4[4] + q1 * dt_s,
        b4[5],
        b5[3],
        b5[4],
        b5[5] + q2 * dt_s,
    )


_KH_FLOOR = 0.3
"""Smallest (K H)_vv the adaptive Q divides by (see BlendNavigator._adapt)."""


def _carry_pos_vel(p: FloatArray, dt_s: float, accel_psd_ned: FloatArray) -> FloatArray:
    """Covariance carried ``dt_s`` forward through ``position += velocity * dt`` with white
    acceleration noise of PSD ``accel_psd_ned`` [m^2/s^3]: the dominant coupling over a
    fraction of a covariance interval. ``p`` is (N_STATE, N_STATE)."""
    carried = p.copy()
    carried[0:3, :] += dt_s * p[3:6, :]  # Phi P: position rows gain dt x velocity rows
    carried[:, 0:3] += dt_s * carried[:, 3:6]  # (Phi P) Phi^T: the same for the columns
    # the white acceleration noise on the diagonals of the four 3x3 blocks, in one indexed
    # add (the same per-element products as the array forms)
    psd = accel_psd_ned.tolist()
    q_pp = [q * dt_s**3 / 3.0 for q in psd]
    q_pv = [q * dt_s**2 / 2.0 for q in psd]
    q_vv = [q * dt_s for q in psd]
    carried.reshape(-1)[_CARRY_NOISE_IDX] += q_pp + q_pv + q_pv + q_vv
    return carried


_CARRY_NOISE_IDX = _flat_index(
    [(i, i) for i in range(3)]
    + [(i, 3 + i) for i in range(3)]
    + [(3 + i, i) for i in range(3)]
    + [(3 + i, 3 + i) for i in range(3)]
)
"""Flat indices of the diagonals of the position/velocity 3x3 blocks (see _carry_pos_vel)."""
