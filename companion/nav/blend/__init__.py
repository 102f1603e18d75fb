"""Adaptive GNSS/INS blend: an error-state Kalman filter with delayed GNSS fusion
(El-Mowafy 2005, "RTK networks for precision approach with an adaptive GPS/INS blend").

States (estimate minus truth, see :mod:`companion.nav.ins`): position (0:3, m),
velocity (3:6, m/s), attitude error psi (6:9, rad), accelerometer bias (9:12, m/s^2),
gyro bias (12:15, rad/s), and the receiver's own position error (15:18, m). Loose
coupling: the GNSS receiver's position and velocity are the measurements, with R from
the accuracies it reports.

GNSS position errors are time-correlated; treated as white, they make the filter
average them away and claim a position covariance far smaller than its error. So by
default (``gnss_error_model="gauss_markov"``) the receiver's position error is a
first-order Gauss-Markov state of the reported variance and a per-fix-type correlation
time, plus a small white part (``gnss_white_fraction``); ``"white"`` keeps the classical
loose coupling (:mod:`.receiver`).

Timing (the ArduPilot EKF3 pattern):

* every IMU sample advances the nominal state (plain floats, :mod:`companion.nav.ins`);
* every ``cov_interval_s`` (default 0.1 s) the 18x18 covariance is propagated once
  through the segment, with F evaluated at the segment's mean NED specific force,
  discretised to second order (trapezoidal Qd) or by Van Loan (``cov_discretisation``;
  :mod:`.error_model`), and the segment is pushed into a ring buffer of ``history_s``
  seconds (:mod:`.history`);
* a GNSS fix valid at ``t_m`` (older than the newest IMU sample) is compared with the
  buffered nominal state at ``t_m`` using the buffered covariance nearest ``t_m``
  (:mod:`.measurement`); the correction is carried forward to the newest IMU time through
  the buffered transition matrices, exact for the linear error model, and the buffered
  snapshots are corrected too.

Adaptive noise (:mod:`.adaptive`): R as a bounded scale on the reported position
variance from the residual form of Mohamed & Schwarz (1999), Q as the accelerometer
noise density per NED axis from the velocity innovations. By default neither may fall
below the receiver's report or the IMU's specification (``r_scale_bounds`` and
``q_scale_bounds`` start at 1): time-correlated GNSS errors look like signal between
fixes, and a window can reliably tell only that noise is larger than modelled.
``BlendConfig(adaptive=False)`` is the non-adaptive baseline.

Without an autopilot attitude the blend aligns itself (:mod:`.alignment`): levelled from
the accelerometer at rest, yaw fitted to the GNSS velocity changes once moving; it then
runs strapdown. Strapdown, the gyro's white noise is measured in use (second differences,
:mod:`companion.nav.imu_check`): while it exceeds the configured density beyond chance the
measured density drives the attitude error (``gyro_noise_measured``). The accelerometer's
white noise is measured likewise, in every mode, and drives the velocity error
(:mod:`.accel_noise`, ``accel_noise_measured``); the receiver's velocity error beyond its
report, measured by its own positions, widens the velocity R (:mod:`.velocity_error`,
``vel_error_measured``). The receiver's reported
accuracies are floored at what the model can
honour between fixes (``pos_std_floor_m``, ``vel_std_floor_mps``).

Modules: :mod:`.config` (:class:`BlendConfig`), :mod:`.filter` (:class:`BlendNavigator`),
:mod:`.alignment`, :mod:`.error_model`, :mod:`.history`, :mod:`.measurement`,
:mod:`.receiver`, :mod:`.adaptive`, :mod:`.accel_noise`, :mod:`.velocity_error`,
:mod:`.diagnostics`. Method notes: ``docs/methods.md``.

References
----------
El-Mowafy (2005) (blend equations, adaptive R and Q, moving window N = 20-30);
Mohamed & Schwarz, "Adaptive Kalman filtering for INS/GPS", J. Geodesy 73 (1999)
eq. 20-28; Mehra, "Approaches to adaptive filtering", IEEE TAC 17(5), 1972; Van Loan,
"Computing integrals involving the matrix exponential", IEEE TAC 23(3), 1978; ArduPilot
AP_NavEKF3 (fusion at the delayed horizon, output predictor).
"""

from companion.nav.blend.config import BlendConfig
from companion.nav.blend.diagnostics import BlendDiagnostics
from companion.nav.blend.filter import BlendNavigator
from companion.nav.blend.receiver import GNSS_ERR_TAU_S

__all__ = ["GNSS_ERR_TAU_S", "BlendConfig", "BlendDiagnostics", "BlendNavigator"]
