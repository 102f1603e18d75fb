"""The simplest navigator: GNSS pass-through with constant-velocity extrapolation.

Between fixes (and through a gap) the position is carried by the last
velocity; the covariance grows as a constant-velocity model driven by white
acceleration noise of spectral density ``q`` [m^2/s^3] per axis:

    P_pos(dt) = P_pos + 2 dt P_pv + dt^2 P_vel + q dt^3 / 3

Horizontally ``q`` is at least Singer's ``2 sigma_m^2 tau`` with ``sigma_m^2`` the
mean square of the flight's own horizontal accelerations (velocity changes over at
least :data:`ACCEL_BASELINE_S`, remembered for :data:`ACCEL_MEMORY_S`): a plane that
turns is not carried with a hovering copter's covariance (Singer 1970, eq. 9).

Its vertical velocity, which GPS_RAW_INT does not carry, is the smoothed
difference of consecutive fix heights. It is the baseline every better
navigator is measured against, and what runs when nothing better is
configured.

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation (2001), section 6.2 (continuous white-noise acceleration model).
Singer, "Estimating optimal tracking filter performance for manned maneuvering
targets", IEEE Trans. AES-6 (1970).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from companion.nav.blend.receiver import DEFAULT_TAU_S, GNSS_ERR_TAU_S
from companion.nav.frames import LocalFrame, rotation_between_frames
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.ranges import check_ranges, ranged
from companion.types import AttitudeSample, FixType, FloatArray, ImuSample

_EYE3 = np.eye(3)
MANOEUVRE_TIME_S = 10.0
"""Singer's manoeuvre time constant tau (his figure for a turn)."""
ACCEL_BASELINE_S = 1.0
"""Velocities this far apart at least give an acceleration (velocity noise stays small)."""
ACCEL_MEMORY_S = 120.0
"""Time constant of the mean square of the flight's horizontal accelerations."""
MAX_ACCEL_GAP_S = 5.0
"""Velocities further apart than this (a gap) give no acceleration."""


@dataclass(frozen=True, slots=True)
class PassthroughConfig:
    """Tuning of the constant-velocity pass-through navigator."""

    accel_psd_m2ps3: float = ranged(0.5, gt=0.0)
    """White acceleration noise spectral density per axis (manoeuvres the model ignores)."""
    gate_false_alarm_prob: float = ranged(1e-4, gt=0.0, lt=1.0)
    """Probability that a good fix fails the 3-dof position gate."""
    vertical_velocity_gain: float = ranged(0.3, gt=0.0, le=1.0)
    """Smoothing gain of the height-difference vertical velocity (0 < gain <= 1)."""
    default_vel_var_m2ps2: float = ranged(0.25, gt=0.0)
    """Velocity variance used when the receiver gives no velocity accuracy."""
    fix_white_fraction: float = ranged(0.1, gt=0.0, le=1.0)
    """Share of a fix's reported position variance that is white from fix to fix; the
    rest wanders with the fix type's correlation time (the blend's receiver model,
    ``blend.gnss_white_fraction``): what the height differences of consecutive fixes
    carry into the vertical velocity."""

    def __post_init__(self) -> None:
        check_ranges(self)


class PassthroughNavigator:
    """GNSS pass-through with constant-velocity extrapolation (implements ``Navigator``)."""

    def __init__(self, config: PassthroughConfig | None = None) -> None:
        self.config = config or PassthroughConfig()
        self._gate = float(chi2.ppf(1.0 - self.config.gate_false_alarm_prob, 3))
        self._accel_ms_m2ps4 = 0.0
        """Mean square of the horizontal acceleration per axis: the manoeuvres seen in
        this flight (kept through a reset of the state: they are the vehicle's)."""
        self.reset()

    def reset(self) -> None:
        """Forget the state."""
        self._t_s: float | None = None
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._p_pos = _EYE3.copy()
        self._p_vel = _EYE3.copy()
        self._diagonal = True
        """Both covariances are diagonal (as every fix leaves them; a frame shift rotates them)."""
        self._accel_ref: tuple[float, float, float, float] | None = None
        """(t_s, north, east velocity, their variance sum) the next acceleration is
        measured from."""

    @property
    def horizontal_psd_m2ps3(self) -> float:
        """Horizontal white acceleration density: the configured ``q``, or Singer's
        ``2 sigma_m^2 tau`` from the manoeuvres seen, whichever is larger."""
        return max(self.config.accel_psd_m2ps3, 2.0 * self._accel_ms_m2ps4 * MANOEUVRE_TIME_S)

    @property
    def initialised(self) -> bool:
        """True after the first fix."""
        return self._t_s is not None

    def on_imu(self, sample: ImuSample) -> None:
        """No use for the IMU."""

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        """No use for the attitude."""

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        """No heading state."""

    def predict(self, t_s: float) -> NavState | None:
        """Constant-velocity extrapolation to ``t_s`` with a growing covariance."""
        if self._t_s is None:
            return None
        dt = max(0.0, t_s - self._t_s)
        p_pos, p_vel = self._grown_cov(dt)
        return NavState(t_s, self._pos + self._vel * dt, self._vel.copy(), p_pos, p_vel)

    def _grown_cov(self, dt: float) -> tuple[FloatArray, FloatArray]:
        """Position and velocity covariances (3, 3) each, ``dt`` s after the last fix."""
        q = self.config.accel_psd_m2ps3
        q_h = self.horizontal_psd_m2ps3
        p_pos = self._p_vel * (dt * dt)
        p_pos += self._p_pos
        p_vel = self._p_vel.copy()
        # the white acceleration noise diag(q_h, q_h, q), added to the diagonals
        dt3 = dt**3 / 3.0
        for axis, qa in ((0, q_h), (1, q_h), (2, q)):
            p_pos[axis, axis] += qa * dt3
            p_vel[axis, axis] += qa * dt
        return p_pos, p_vel

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Gate the fix against the extrapolation, then take it as the new state."""
        pos_var = meas.pos_var_ned_m2.tolist()
        if self._t_s is None:
            self._take(meas, pos_var, False)
            return GnssUpdate(meas.t_s, True, 0.0, 3, self._gate, np.zeros(3), np.diag(pos_var))
        dt = max(0.0, meas.t_s - self._t_s)
        s_cov, _ = self._grown_cov(dt)
        s_cov.reshape(-1)[::4] += meas.pos_var_ned_m2
        innov = meas.pos_ned_m - (self._pos + self._vel * dt)
        if self._diagonal:
            # S is diagonal: S^-1 nu is nu_i / S_ii
            n0, n1, n2 = innov.tolist()
            nis = n0 * n0 / s_cov[0, 0] + n1 * n1 / s_cov[1, 1] + n2 * n2 / s_cov[2, 2]
        else:
            nis = float(innov @ np.linalg.solve(s_cov, innov))
        if gate and nis > self._gate:
            return GnssUpdate(meas.t_s, False, nis, 3, self._gate, innov, s_cov, "gate")
        self._take(meas, pos_var, True)
        return GnssUpdate(meas.t_s, True, nis, 3, self._gate, innov, s_cov)

    def _take(self, meas: GnssMeasurement, pos_var: list[float], predicted: bool) -> None:
        cfg = self.config
        isfinite = math.isfinite
        vel = [float(v) for v in meas.vel_ned_mps]
        default_var = cfg.default_vel_var_m2ps2
        vel_var = [
            v if isfinite(v) else default_var for v in (float(v) for v in meas.vel_var_ned_m2ps2)
        ]
        if predicted and self._t_s is not None and meas.t_s > self._t_s:
            dt = meas.t_s - self._t_s
            pos = meas.pos_ned_m.tolist()
            old_pos = self._pos.tolist()
            old_vel = self._vel.tolist()
            k = cfg.vertical_velocity_gain
            for axis in range(3):
                if not isfinite(vel[axis]):
                    diff_vel = (pos[axis] - old_pos[axis]) / dt
                    vel[axis] = (1.0 - k) * old_vel[axis] + k * diff_vel
                    # EWMA of height differences: v = (1-k) v + k d, d = dz / dt, with the
                    # fixes' errors as the receiver model has them (ewma_step_var_m2)
                    vel_var[axis] = (1.0 - k) ** 2 * float(self._p_vel[axis, axis]) + (
                        k**2 * ewma_step_var_m2(pos_var[axis], dt, meas.fix_type, k, cfg) / dt**2
                    )
        else:
            vel = [v if isfinite(v) else 0.0 for v in vel]
        if isfinite(float(meas.vel_ned_mps[0])) and isfinite(float(meas.vel_ned_mps[1])):
            self._learn_accel(meas.t_s, vel[0], vel[1], vel_var[0] + vel_var[1])
        self._t_s = meas.t_s
        self._pos = np.array(meas.pos_ned_m, dtype=float)
        self._vel = np.array(vel)
        self._p_pos = np.diag(pos_var)
        self._p_vel = np.diag(vel_var)
        self._diagonal = True

    def _learn_accel(self, t_s: float, vn_mps: float, ve_mps: float, var_m2ps2: float) -> None:
        """The mean square of the horizontal acceleration, from velocities at least
        :data:`ACCEL_BASELINE_S` apart (never across a gap or backwards in time), less
        what the two velocities' noise (``var_m2ps2``: north + east variance) explains."""
        ref = self._accel_ref
        if ref is not None and ACCEL_BASELINE_S > t_s - ref[0] >= 0.0:
            return
        if ref is not None and t_s - ref[0] <= MAX_ACCEL_GAP_S:
            dt = t_s - ref[0]
            dv2 = (vn_mps - ref[1]) ** 2 + (ve_mps - ref[2]) ** 2 - var_m2ps2 - ref[3]
            a2 = max(dv2, 0.0) / (2.0 * dt * dt)
            w = 1.0 - math.exp(-dt / ACCEL_MEMORY_S)
            self._accel_ms_m2ps4 += w * (a2 - self._accel_ms_m2ps4)
        self._accel_ref = (t_s, vn_mps, ve_mps, var_m2ps2)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express position, velocity and covariances in ``new``."""
        self._accel_ref = None
        if self._t_s is None:
            return
        rot = rotation_between_frames(old, new)
        lat, lon, alt = old.ned_to_lla(self._pos)
        self._pos = new.lla_to_ned(lat, lon, alt)
        self._vel = rot @ self._vel
        self._p_pos = rot @ self._p_pos @ rot.T
        self._p_vel = rot @ self._p_vel @ rot.T
        self._diagonal = False


def ewma_step_var_m2(
    var_m2: float, dt_s: float, fix_type: FixType, gain: float, cfg: PassthroughConfig
) -> float:
    """What one step of the height-difference EWMA, ``v_k = (1 - k) v_(k-1) + k (z_k -
    z_(k-1)) / dt``, adds to the velocity's variance, times ``dt^2 / k^2``, for fixes of
    reported variance ``var_m2`` ``dt_s`` apart.

    The receiver's error is a white share ``w`` of the variance and a first-order
    Gauss-Markov rest of the fix type's correlation time ``tau``
    (:data:`~companion.nav.blend.receiver.GNSS_ERR_TAU_S`: the blend's receiver model).
    The Gauss-Markov share adds its increment's variance, ``2 (1 - w) var (1 -
    e^(-dt/tau))``; a white error enters one difference with a plus and the next with a
    minus, which the EWMA's carried part cancels all but ``k`` of: ``2 k w var`` (the
    exact recursion, whose steady state is the EWMA of differences of white noise,
    ``2 k^2 w var / ((2 - k) dt^2)``). Taking every fix's error as white and independent,
    ``2 var``, made a 3-D receiver's vertical velocity about 30 times as uncertain as it
    is at 5 Hz."""
    w = cfg.fix_white_fraction
    tau = GNSS_ERR_TAU_S.get(fix_type, DEFAULT_TAU_S)
    return 2.0 * var_m2 * (gain * w + (1.0 - w) * -math.expm1(-dt_s / tau))


def speed_mps(vel_ned_mps: FloatArray) -> float:
    """Horizontal speed of an NED velocity, m/s."""
    return float(np.hypot(vel_ned_mps[0], vel_ned_mps[1]))
