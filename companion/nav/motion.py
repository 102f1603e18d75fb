"""Motion models that carry position through a GNSS gap.

The lesson of "Tracking with the aircraft's kinematic and dynamic parameters": a
tracker whose motion model is a stationary-acceleration guess (constant velocity,
constant acceleration, Singer) diverges in manoeuvres; the model that carries position
through a gap should be the aircraft's own measured specific force. In ``companion``
that model *is* the INS (:mod:`companion.nav.ins`, used by
:class:`companion.nav.blend.BlendNavigator`).

This module keeps the baseline it is measured against, and what runs when no
IMU stream is present: Singer's model per NED axis, as a
:class:`companion.nav.navigator.Navigator`. Per axis the state is position,
velocity and acceleration, the acceleration a first-order Gauss-Markov process
with manoeuvre time constant ``1/alpha_m``:

    p(k) = p(k-1) + v(k-1) T + a(k-1) T^2 / 2
    v(k) = v(k-1) + a(k-1) T
    a(k) = (1 - alpha_m T) a(k-1) + xi(k-1)

discretised exactly (Van Loan) from the continuous model
``da/dt = -alpha_m a + w``, ``E[w w] = 2 alpha_m sigma_m^2``. The constant-velocity
baseline is :class:`companion.nav.passthrough.PassthroughNavigator`.

References
----------
"Tracking with the aircraft's kinematic and dynamic parameters" (the Singer model
and its failure in manoeuvres); Singer, "Estimating optimal tracking filter performance
for manned maneuvering targets", IEEE TAES 6(4), 1970.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from companion.nav.frames import LocalFrame, rotation_between_frames
from companion.nav.gnss import FALLBACK_STD_M, UNKNOWN_STD_M
from companion.nav.kalman import chi2_gate, joseph_update, predict_covariance, van_loan
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.ranges import check_ranges, ranged
from companion.types import AttitudeSample, FloatArray, ImuSample

log = logging.getLogger(__name__)

_N = 9
"""State: position (0:3), velocity (3:6), acceleration (6:9), NED."""


@dataclass(frozen=True, slots=True)
class SingerConfig:
    """Configuration of :class:`SingerNavigator`."""

    maneuver_tau_s: float = ranged(20.0, gt=0.0)
    """Manoeuvre time constant 1/alpha_m, s (the acceleration's correlation time)."""
    accel_sigma_mps2: tuple[float, float, float] = ranged((1.5, 1.5, 0.5), gt=0.0, length=3)
    """Steady-state 1-sigma of the manoeuvre acceleration per N, E, D axis, m/s^2."""
    gate_false_alarm_prob: float = ranged(1e-4, gt=0.0, lt=1.0)
    """Probability that a consistent fix fails the innovation chi-square gate."""
    vel_std_fallback_mps: float = ranged(0.3, gt=0.0)
    """Velocity 1-sigma when the receiver reported none, m/s."""
    init_vel_sigma_mps: float = ranged(5.0, gt=0.0)
    """Velocity 1-sigma at start on axes the first fix gives no velocity for, m/s."""
    pos_std_floor_m: float = ranged(0.01, gt=0.0)
    """Floor of the position measurement 1-sigma, m."""
    vel_std_floor_mps: float = ranged(0.02, gt=0.0)
    """Floor of the velocity measurement 1-sigma, m/s."""

    def __post_init__(self) -> None:
        check_ranges(self)


def singer_matrices(
    dt_s: float, maneuver_tau_s: float, accel_sigma_mps2: tuple[float, float, float]
) -> tuple[FloatArray, FloatArray]:
    """Transition Phi (9, 9) and process noise Qd (9, 9) of the 3-axis Singer model over dt.

    References
    ----------
    Singer (1970) eq. 3-4 (continuous model); discretised by Van Loan (1978).
    """
    alpha = 1.0 / maneuver_tau_s
    f = np.zeros((_N, _N))
    f[0:3, 3:6] = np.eye(3)
    f[3:6, 6:9] = np.eye(3)
    f[6:9, 6:9] = -alpha * np.eye(3)
    gqg = np.zeros((_N, _N))
    gqg[6:9, 6:9] = np.diag(2.0 * alpha * np.asarray(accel_sigma_mps2) ** 2)
    return van_loan(f, gqg, dt_s)


class SingerNavigator:
    """Singer's model per NED axis fed by GNSS only (implements ``Navigator``; no IMU)."""

    def __init__(self, config: SingerConfig | None = None) -> None:
        self.config = config or SingerConfig()
        self._gates = {m: chi2_gate(self.config.gate_false_alarm_prob, m) for m in range(1, 7)}
        self.rejected: dict[str, int] = {}
        self.reset()

    @property
    def initialised(self) -> bool:
        """True after the first fix."""
        return self._t_s is not None

    def reset(self) -> None:
        """Forget the state."""
        self._t_s: float | None = None
        self._x = np.zeros(_N)
        self._p = np.eye(_N)

    def on_imu(self, sample: ImuSample) -> None:
        """No use for the IMU (this is the model that runs without one)."""

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        """No use for the attitude."""

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        """No heading state."""

    def _propagate(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        if self._t_s is None:
            raise ValueError("propagate on an uninitialised navigator")
        dt = t_s - self._t_s
        if dt <= 0.0:
            return self._x.copy(), self._p.copy()
        cfg = self.config
        phi, qd = singer_matrices(dt, cfg.maneuver_tau_s, cfg.accel_sigma_mps2)
        return phi @ self._x, predict_covariance(self._p, phi, qd)

    def predict(self, t_s: float) -> NavState | None:
        """The state carried to ``t_s`` by the Singer model, unchanged."""
        if self._t_s is None:
            return None
        x, p = self._propagate(max(t_s, self._t_s))
        return NavState(t_s, x[0:3].copy(), x[3:6].copy(), p[0:3, 0:3].copy(), p[3:6, 3:6].copy())

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Propagate to the fix time, gate and fuse position (and velocity where given)."""
        if not (np.all(np.isfinite(meas.pos_ned_m)) and math.isfinite(meas.t_s)):
            return self._refuse(meas, "position_not_finite")
        r_pos, r_vel = self._variances(meas)
        vel = np.asarray(meas.vel_ned_mps, dtype=float)
        vel_ok = np.isfinite(vel)
        if self._t_s is None:
            self._x = np.zeros(_N)
            self._x[0:3] = meas.pos_ned_m
            self._x[3:6] = np.where(vel_ok, vel, 0.0)
            p = np.zeros((_N, _N))
            p[0:3, 0:3] = np.diag(r_pos)
            p[3:6, 3:6] = np.diag(np.where(vel_ok, r_vel, self.config.init_vel_sigma_mps**2))
            p[6:9, 6:9] = np.diag(np.asarray(self.config.accel_sigma_mps2) ** 2)
            self._p = p
            self._t_s = meas.t_s
            return GnssUpdate(
                meas.t_s, True, 0.0, 3, self._gates[3], np.zeros(3), np.diag(r_pos), "init"
            )
        if meas.t_s < self._t_s:
            return self._refuse(meas, "fix_out_of_order")
        x, p = self._propagate(meas.t_s)
        axes = np.flatnonzero(vel_ok)
        m = 3 + len(axes)
        h = np.zeros((m, _N))
        h[0:3, 0:3] = np.eye(3)
        z = np.empty(m)
        r = np.empty(m)
        z[0:3] = meas.pos_ned_m
        r[0:3] = r_pos
        for k, axis in enumerate(axes):
            h[3 + k, 3 + axis] = 1.0
            z[3 + k] = vel[axis]
            r[3 + k] = r_vel[axis]
        nu = z - h @ x
        try:
            corr = joseph_update(p, nu, h, np.diag(r))
        except ValueError:
            return self._refuse(meas, "innovation_cov_not_pd")
        threshold = self._gates[m]
        s_pos = corr.innov_cov[0:3, 0:3]
        if gate and corr.nis > threshold:
            return GnssUpdate(meas.t_s, False, corr.nis, m, threshold, nu[0:3], s_pos, "gate")
        self._x = x + corr.dx
        self._p = corr.p_post
        self._t_s = meas.t_s
        return GnssUpdate(meas.t_s, True, corr.nis, m, threshold, nu[0:3], s_pos)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express position, velocity, acceleration and covariance in ``new``."""
        if self._t_s is None:
            return
        rot = rotation_between_frames(old, new)
        lat, lon, alt = old.ned_to_lla(self._x[0:3])
        self._x[0:3] = new.lla_to_ned(lat, lon, alt)
        self._x[3:6] = rot @ self._x[3:6]
        self._x[6:9] = rot @ self._x[6:9]
        t = np.kron(np.eye(3), rot)
        self._p = t @ self._p @ t.T

    def _variances(self, meas: GnssMeasurement) -> tuple[FloatArray, FloatArray]:
        cfg = self.config
        h_std, v_std = FALLBACK_STD_M.get(meas.fix_type, UNKNOWN_STD_M)
        fallback = np.array([h_std**2, h_std**2, v_std**2])
        r_pos = np.asarray(meas.pos_var_ned_m2, dtype=float)
        r_pos = np.where(np.isfinite(r_pos) & (r_pos > 0.0), r_pos, fallback)
        r_pos = np.maximum(r_pos, cfg.pos_std_floor_m**2)
        r_vel = np.asarray(meas.vel_var_ned_m2ps2, dtype=float)
        r_vel = np.where(np.isfinite(r_vel) & (r_vel > 0.0), r_vel, cfg.vel_std_fallback_mps**2)
        return r_pos, np.maximum(r_vel, cfg.vel_std_floor_mps**2)

    def _refuse(self, meas: GnssMeasurement, reason: str) -> GnssUpdate:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        if self.rejected[reason] in (1, 10, 100, 1000):
            log.warning("singer rejected a fix (%s), %d so far", reason, self.rejected[reason])
        nan3 = np.full(3, np.nan)
        return GnssUpdate(
            meas.t_s, False, math.nan, 0, math.nan, nan3, np.full((3, 3), np.nan), reason
        )
