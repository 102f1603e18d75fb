"""The simplest navigator: GNSS pass-through with constant-velocity extrapolation.

Between fixes (and through a gap) the position is carried by the last
velocity; the covariance grows as a constant-velocity model driven by white
acceleration noise of spectral density ``q`` [m^2/s^3] per axis:

    P_pos(dt) = P_pos + 2 dt P_pv + dt^2 P_vel + q dt^3 / 3

Its vertical velocity, which GPS_RAW_INT does not carry, is the smoothed
difference of consecutive fix heights. It is the baseline every better
navigator is measured against, and what runs when nothing better is
configured.

References
----------
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation (2001), section 6.2 (continuous white-noise acceleration model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from companion.nav.frames import LocalFrame
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState, rotation_between_frames
from companion.types import AttitudeSample, FloatArray, ImuSample

_EYE3 = np.eye(3)


@dataclass(frozen=True, slots=True)
class PassthroughConfig:
    """Tuning of the constant-velocity pass-through navigator."""

    accel_psd_m2ps3: float = 0.5
    """White acceleration noise spectral density per axis (manoeuvres the model ignores)."""
    gate_false_alarm_prob: float = 1e-4
    """Probability that a good fix fails the 3-dof position gate."""
    vertical_velocity_gain: float = 0.3
    """Smoothing gain of the height-difference vertical velocity (0 < gain <= 1)."""
    default_vel_var_m2ps2: float = 0.25
    """Velocity variance used when the receiver gives no velocity accuracy."""

    def __post_init__(self) -> None:
        if self.accel_psd_m2ps3 <= 0.0:
            raise ValueError("accel_psd_m2ps3 must be > 0")
        if not 0.0 < self.gate_false_alarm_prob < 1.0:
            raise ValueError("gate_false_alarm_prob must be in (0, 1)")
        if not 0.0 < self.vertical_velocity_gain <= 1.0:
            raise ValueError("vertical_velocity_gain must be in (0, 1]")
        if self.default_vel_var_m2ps2 <= 0.0:
            raise ValueError("default_vel_var_m2ps2 must be > 0")


class PassthroughNavigator:
    """GNSS pass-through with constant-velocity extrapolation (implements ``Navigator``)."""

    def __init__(self, config: PassthroughConfig | None = None) -> None:
        self.config = config or PassthroughConfig()
        self._gate = float(chi2.ppf(1.0 - self.config.gate_false_alarm_prob, 3))
        self.reset()

    def reset(self) -> None:
        """Forget the state."""
        self._t_s: float | None = None
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._p_pos = _EYE3.copy()
        self._p_vel = _EYE3.copy()

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
        q = self.config.accel_psd_m2ps3
        p_pos = self._p_pos + dt * dt * self._p_vel + (q * dt**3 / 3.0) * _EYE3
        p_vel = self._p_vel + (q * dt) * _EYE3
        return NavState(t_s, self._pos + self._vel * dt, self._vel.copy(), p_pos, p_vel)

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Gate the fix against the extrapolation, then take it as the new state."""
        r_pos = np.diag(meas.pos_var_ned_m2)
        if self._t_s is None:
            self._take(meas, None)
            return GnssUpdate(meas.t_s, True, 0.0, 3, self._gate, np.zeros(3), r_pos)
        pred = self.predict(meas.t_s)
        if pred is None:  # cannot happen once initialised; keeps mypy honest
            raise ValueError("predict returned None on an initialised navigator")
        innov = meas.pos_ned_m - pred.pos_ned_m
        s_cov = pred.pos_cov_ned_m2 + r_pos
        nis = float(innov @ np.linalg.solve(s_cov, innov))
        if gate and nis > self._gate:
            return GnssUpdate(meas.t_s, False, nis, 3, self._gate, innov, s_cov, "gate")
        self._take(meas, pred)
        return GnssUpdate(meas.t_s, True, nis, 3, self._gate, innov, s_cov)

    def _take(self, meas: GnssMeasurement, pred: NavState | None) -> None:
        cfg = self.config
        vel = np.array(meas.vel_ned_mps, dtype=float)
        vel_var = np.array(meas.vel_var_ned_m2ps2, dtype=float)
        vel_var = np.where(np.isfinite(vel_var), vel_var, cfg.default_vel_var_m2ps2)
        if pred is not None and self._t_s is not None and meas.t_s > self._t_s:
            dt = meas.t_s - self._t_s
            diff_vel = (meas.pos_ned_m - self._pos) / dt
            k = cfg.vertical_velocity_gain
            for axis in range(3):
                if not np.isfinite(vel[axis]):
                    vel[axis] = (1.0 - k) * self._vel[axis] + k * diff_vel[axis]
                    # EWMA of height differences: v = (1-k) v + k d, var(d) = 2 sigma^2 / dt^2
                    vel_var[axis] = (1.0 - k) ** 2 * self._p_vel[axis, axis] + (
                        k**2 * 2.0 * meas.pos_var_ned_m2[axis] / dt**2
                    )
        else:
            vel = np.where(np.isfinite(vel), vel, 0.0)
        self._t_s = meas.t_s
        self._pos = np.array(meas.pos_ned_m, dtype=float)
        self._vel = vel
        self._p_pos = np.diag(meas.pos_var_ned_m2)
        self._p_vel = np.diag(vel_var)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express position, velocity and covariances in ``new``."""
        if self._t_s is None:
            return
        rot = rotation_between_frames(old, new)
        lat, lon, alt = old.ned_to_lla(self._pos)
        self._pos = new.lla_to_ned(lat, lon, alt)
        self._vel = rot @ self._vel
        self._p_pos = rot @ self._p_pos @ rot.T
        self._p_vel = rot @ self._p_vel @ rot.T


def speed_mps(vel_ned_mps: FloatArray) -> float:
    """Horizontal speed of an NED velocity, m/s."""
    return float(np.hypot(vel_ned_mps[0], vel_ned_mps[1]))
